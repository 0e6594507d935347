//! The MJCF loader: any bytes give a model or an error, never a panic, abort or hang.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = envs::mjcf::load_str(text, "fuzz.xml");
    }
});
