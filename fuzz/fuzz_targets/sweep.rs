//! The sweep file reader, then the expansion into runs (each configuration resolved), as
//! `meben ablate` does before training anything.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data)
        && let Ok(sweep) = rl::Sweep::parse(text, "fuzz.toml")
    {
        let _ = sweep.runs();
    }
});
