//! cargo-fuzz target: vmt::fuzz::profile_csv never panics on any input (issue 14).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    vmt::fuzz::profile_csv(data);
});
