#![no_main]
//! Fuzzes `lidarcal::io::parse_points` with `FileFormat::Text`.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    lidarcal_fuzz::check(data, lidarcal::io::FileFormat::Text);
});
