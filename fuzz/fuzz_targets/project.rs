//! Project and recovery files: never a panic, an error of one line naming the field.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data)
        && let Err(e) = makeit4d::project::Project::from_json(text)
    {
        assert!(!format!("{e:#}").contains('\n'));
    }
});
