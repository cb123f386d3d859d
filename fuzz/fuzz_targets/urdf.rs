//! cargo-fuzz target: vmt::fuzz::urdf never panics on any input (issue 14).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    vmt::fuzz::urdf(data);
});
