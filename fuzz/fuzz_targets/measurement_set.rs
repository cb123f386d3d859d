//! cargo-fuzz target: vmt::fuzz::measurement_set never panics on any input (issue 14).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    vmt::fuzz::measurement_set(data);
});
