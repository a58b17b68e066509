//! `fishtrack compare --rect-alpha canvas`: the no-heap core and the float
//! reference agree on a haul rectified onto a canvas that keeps every raw
//! pixel (curved raw view borders for the tracker, water-filled margins,
//! the newborn's default velocity scaled by the raw view's width), as they
//! do at the default scaling.

use fishtrack_tests::{run_fishtrack as run, text};

#[test]
fn core_and_reference_agree_on_a_canvas() {
    let dir = tempfile::tempdir().unwrap();
    let h = dir.path().join("haul");
    let h = h.to_str().unwrap();
    let out = run(&[
        "synth", h, "--size", "768", "--frames", "10", "--seed", "11",
    ]);
    assert!(out.status.success(), "synth: {}", text(&out.stderr));
    for extra in [&[][..], &["--rect-alpha", "canvas"][..]] {
        let mut args = vec!["compare", h];
        args.extend_from_slice(extra);
        let out = run(&args);
        let so = text(&out.stdout);
        assert!(
            out.status.success(),
            "{extra:?}: {so}\n{}",
            text(&out.stderr)
        );
        assert!(so.contains("core and reference agree"), "{extra:?}: {so}");
        // the table covers the tracker: some track assignments compared
        let line = so
            .lines()
            .find(|l| l.starts_with("track assignments identical"))
            .unwrap();
        assert!(!line.contains(" 0/0 "), "{extra:?}: {line}");
    }
}
