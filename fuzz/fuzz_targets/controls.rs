//! The controls file of `meben sim --controls` (the first byte chooses the actuator count).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Some((&n, rest)) = data.split_first()
        && let Ok(text) = std::str::from_utf8(rest)
    {
        let _ = envs::rollout_tool::parse_controls(text, "fuzz.csv", usize::from(n % 32));
    }
});
