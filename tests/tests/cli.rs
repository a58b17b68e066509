//! The `fishtrack` command line as a user sees it (DESIGN.md, "Command
//! line"): the subcommands it lists, and exit code 2 with a message naming
//! the subcommand or file for bad input and for subcommands not built yet.
//!
//! The binary belongs to another package (`fishtrack`), so cargo neither
//! builds it for these tests nor sets `CARGO_BIN_EXE_fishtrack` here (bins
//! are only built for integration tests of their own package). [`fishtrack`]
//! therefore runs `cargo build -p fishtrack --bin fishtrack` once, for the
//! profile these tests were built with (cargo has released its build lock by
//! the time tests run; up to date, this is a no-op), so the tests never run a
//! stale binary, and fails with a clear message if the binary is still
//! missing.

use fishtrack_tests::{run_fishtrack as run, text};

/// The subcommands DESIGN.md promises.
const SUBCOMMANDS: [&str; 7] = [
    "demo",
    "synth",
    "track",
    "eval",
    "compare",
    "bench",
    "timing-check",
];

#[test]
fn help_lists_the_design_subcommands() {
    let out = run(&["--help"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let help = text(&out.stdout);
    // clap prints "Commands:" then one "  name  about" line per subcommand.
    let listed: Vec<&str> = help
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    for sub in SUBCOMMANDS {
        assert!(listed.contains(&sub), "`{sub}` missing from:\n{help}");
    }
    // Each subcommand has its own help.
    for sub in SUBCOMMANDS {
        let out = run(&[sub, "--help"]);
        assert_eq!(out.status.code(), Some(0), "{sub} --help");
        assert!(text(&out.stdout).contains("Usage:"), "{sub} --help");
    }
}

#[test]
fn usage_errors_exit_2() {
    let out = run(&["no-such-subcommand"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("no-such-subcommand"));
    let out = run(&["track"]); // HAUL and --out are required
    assert_eq!(out.status.code(), Some(2));
    let out = run::<&str>(&[]);
    assert_eq!(out.status.code(), Some(2));
}

/// Every haul-reading subcommand, given a haul directory that does not
/// exist, exits 2: either "not built yet" naming the subcommand, or a
/// bad-input error naming the missing directory.
#[test]
fn bad_haul_or_unbuilt_subcommand_exits_2() {
    let t = tempfile::tempdir().unwrap();
    let missing = t.path().join("no-such-haul");
    let m = missing.to_str().unwrap();
    let out_dir = t.path().join("out");
    let o = out_dir.to_str().unwrap();
    let mut unbuilt = 0;
    for (sub, args) in [
        ("track", vec!["track", m, "--out", o]),
        ("eval", vec!["eval", m, o]),
        ("compare", vec!["compare", m]),
        ("bench", vec!["bench", m]),
    ] {
        let out = run(&args);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        if err.contains("not built yet") {
            unbuilt += 1;
            assert!(err.contains(&format!("fishtrack {sub}")), "{err}");
        } else {
            assert!(
                err.contains("no-such-haul"),
                "{args:?} must name the haul: {err}"
            );
        }
    }
    eprintln!("{unbuilt} of 4 haul subcommands are not built yet");
}

/// Subcommands whose valid-input run does real work are only checked while
/// they are still unbuilt: then they must exit 2 saying so. (`demo` is not
/// run at all: built, it synthesises and tracks a whole haul.)
#[test]
fn unbuilt_subcommands_say_so() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("haul");
    let port = t.path().join("no-such-tty");
    for (sub, args) in [
        (
            "synth",
            vec![
                "synth",
                dir.to_str().unwrap(),
                "--frames",
                "1",
                "--size",
                "64",
            ],
        ),
        (
            "timing-check",
            vec!["timing-check", "--port", port.to_str().unwrap()],
        ),
    ] {
        let out = run(&args);
        let err = text(&out.stderr);
        if err.contains("not built yet") {
            assert_eq!(out.status.code(), Some(2), "{sub}: {err}");
            assert!(err.contains(&format!("fishtrack {sub}")), "{err}");
        } else if sub == "timing-check" {
            assert_ne!(out.status.code(), Some(0), "no such port: {err}");
            assert!(err.contains("no-such-tty"), "must name the port: {err}");
        }
    }
}

/// `fishtrack bench --json` on a small synthetic haul: every documented
/// key is present, the figures are consistent with each other and with the
/// haul, and the pipeline state fits its 512 KiB limit.
#[test]
fn bench_json_reports_every_key() {
    let t = tempfile::tempdir().unwrap();
    let haul = t.path().join("haul");
    let h = haul.to_str().unwrap();
    let out = run(&["synth", h, "--frames", "3", "--size", "192", "--seed", "3"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let out = run(&["bench", h, "--json", "--repeats", "2"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("bench --json is not JSON ({e}): {}", text(&out.stdout)));
    // the rectified frame: the default canvas holds every raw pixel
    let (fw, fh) = (
        v["width"].as_u64().unwrap_or(0),
        v["height"].as_u64().unwrap_or(0),
    );
    assert!(
        (192..=384).contains(&fw) && (192..=384).contains(&fh),
        "{v}"
    );
    assert_eq!(v["pairs"], 3);
    assert_eq!(v["repeats"], 2);
    let num = |k: &str| {
        v[k].as_f64()
            .unwrap_or_else(|| panic!("{k} missing or not a number: {v}"))
    };
    assert!(num("core_pairs_per_s") > 0.0);
    assert!(num("end_to_end_pairs_per_s") > 0.0);
    let state = num("pipeline_state_bytes");
    assert!(
        state > 100_000.0 && state <= num("pipeline_state_limit_bytes"),
        "{v}"
    );
    assert_eq!(num("pipeline_state_limit_bytes"), 524_288.0);
    // the workspace holds at least the two frame buffers of the frame
    assert!(num("workspace_bytes") >= 2.0 * (fw * fh) as f64, "{v}");
    // peak RSS covers at least the workspace it allocated
    assert!(num("peak_rss_bytes") >= num("workspace_bytes"), "{v}");
    let stages = v["stage_ms_per_pair"]
        .as_object()
        .unwrap_or_else(|| panic!("stage_ms_per_pair missing: {v}"));
    for k in [
        "read",
        "rectify",
        "mesh_removal",
        "coarse",
        "local_segmentation",
        "segmentation",
        "stereo",
        "length",
        "tracking",
        "core_total",
    ] {
        let ms = stages
            .get(k)
            .and_then(|x| x.as_f64())
            .unwrap_or_else(|| panic!("stage {k} missing: {v}"));
        assert!(ms.is_finite() && ms >= 0.0, "{k}: {ms}");
    }
    // the stages of the pipeline are parts of its whole (medians of the
    // same pairs, so allow for the median of a sum not being a sum)
    let part = |k: &str| stages[k].as_f64().unwrap_or(0.0);
    assert!(
        part("segmentation") <= 1.5 * part("core_total") + 0.5,
        "{v}"
    );
    assert!(part("core_total") > 0.0 && part("rectify") > 0.0 && part("read") > 0.0);
    // pairs/s and the per-pair core time describe the same runs
    let core_ms = 1e3 / num("core_pairs_per_s");
    assert!(
        core_ms < 100.0 * (part("core_total") + 1.0),
        "{core_ms} vs {v}"
    );

    // `--rect-alpha 0.25`: the raw frame's size
    let out = run(&[
        "bench",
        h,
        "--json",
        "--repeats",
        "1",
        "--rect-alpha",
        "0.25",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (v["width"].as_u64(), v["height"].as_u64()),
        (Some(192), Some(192))
    );

    // a bad haul: exit 2, naming it
    let missing = t.path().join("no-such-haul");
    let out = run(&["bench", missing.to_str().unwrap(), "--json"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("no-such-haul"));
    // a haul without frames: exit 2
    let empty = t.path().join("empty");
    std::fs::create_dir_all(empty.join("left")).unwrap();
    std::fs::create_dir_all(empty.join("right")).unwrap();
    let out = run(&["bench", empty.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
}
