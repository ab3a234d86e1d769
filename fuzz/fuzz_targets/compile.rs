//! Any accepted expression lowers to WGSL that naga validates.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(e) = filterjit::parse_expr(text) {
        filterjit::jit::compile(&e).expect("every well-typed expression compiles");
    }
});
