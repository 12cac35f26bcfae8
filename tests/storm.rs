//! A short edit storm on the real editor, headless (`makeit4d bench storm` runs 10 000): every
//! change of the project is a recorded edit, an undo or a redo; undo reaches the opened project
//! and redo the last; saves reopen equal; the scene settles; nothing panics.

use makeit4d::app::storm::{StormOptions, run};
use std::path::Path;
use std::time::Duration;

#[test]
fn a_short_storm_keeps_every_invariant() {
    let dir = tempfile::tempdir().unwrap();
    let options = StormOptions {
        open: Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg"),
        edits: 300,
        seed: 7,
        dir: dir.path().join("storm"),
        checkpoint_every: 100,
        settle_limit: Duration::from_secs(300),
    };
    let report = run(&options, |line| eprintln!("{line}")).unwrap();
    eprintln!("{}", report.to_markdown());
    assert!(report.passed(), "{}", report.to_markdown());
    assert_eq!(report.edits, 300);
    assert!(report.recorded > 50, "{report:?}");
    assert!(
        report.undos > 10 && report.saves > 0 && report.checkpoints == 3,
        "{report:?}"
    );
    assert!(report.input_events > 10, "{report:?}");
    // Bounded: a few hundred MiB and a dozen threads on this photo.
    assert!(report.peak_rss_last_mib < 2048.0, "{report:?}");
    assert!(report.max_threads_last < 64, "{report:?}");
}
