//! cargo-fuzz target: vmt::fuzz::scenario_toml never panics on any input (issue 14).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    vmt::fuzz::scenario_toml(data);
});
