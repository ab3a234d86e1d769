//! Any text: the parser and checker never panic; every error has a position
//! inside the text; every accepted expression round-trips through the printer.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    match filterjit::parse_expr(text) {
        Ok(e) => assert_eq!(filterjit::parse_expr(&e.to_string()).unwrap(), e),
        Err(err) => {
            assert!(err.line >= 1 && err.column >= 1 && err.offset <= text.len());
            let _ = err.to_string();
        }
    }
});
