//! Every configuration and calibration file shipped in `config/` parses and validates.

use assess::{AssessConfig, Workspace};
use hrc_adapt_tests::config_dir;

#[test]
fn assess_toml_is_valid_and_equals_the_defaults() {
    // The shipped file documents every key with its default; if a default changes in code, this
    // test makes the file follow.
    let cfg = AssessConfig::from_toml_file(config_dir().join("assess.toml")).unwrap();
    assert_eq!(cfg, AssessConfig::default());
}

#[test]
fn every_workspace_calibration_loads() {
    let mut n = 0;
    for entry in std::fs::read_dir(config_dir()).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        if name.ends_with("workspace.toml") {
            let ws = Workspace::from_toml_file(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(
                ws.len() >= 4,
                "{name}: the four roles need at least four areas"
            );
            for role in assess::AreaRole::ALL {
                assert!(
                    ws.by_role(role).is_some(),
                    "{name}: no area has role {}",
                    role.short()
                );
            }
            n += 1;
        }
    }
    assert!(n >= 1, "no workspace calibration found in config/");
}

#[test]
fn config_loader_names_the_key_and_the_rule() {
    // Issue 2: the loader rejects bad cost orders, weights, τ, M and unknown keys, naming the
    // key and the rule.
    let cases = [
        (
            "[switching]\ncost_high = 2.0",
            "switching.cost_high",
            "c_high > c_int > c_base > 0",
        ),
        (
            "[switching]\ncost_base = 0.0",
            "switching.cost_base",
            "c_high > c_int > c_base > 0",
        ),
        (
            "[switching]\ncost_int = 0.5",
            "switching.cost_int",
            "c_high > c_int > c_base > 0",
        ),
        (
            "[composite]\nweights = { aed = 0.3, tid = 0.2, icd = 0.2, asd = 0.2, ohd = 0.2 }",
            "composite.weights",
            "sum to 1",
        ),
        (
            "[composite]\nweights = { aed = -0.2, tid = 0.4, icd = 0.4, asd = 0.2, ohd = 0.2 }",
            "composite.weights.aed",
            "≥ 0",
        ),
        (
            "[fusion]\nweights = { head = 0.7, body = 0.25, hand = 0.15 }",
            "fusion.weights",
            "sum to 1",
        ),
        ("[fusion]\ntau = 0.0", "fusion.tau", "(0, 1]"),
        ("[fusion]\ntau = 1.2", "fusion.tau", "(0, 1]"),
        (
            "[confirmation]\nwindow_frames = 0",
            "confirmation.window_frames",
            "M must be ≥ 1",
        ),
        ("[fusion]\ntaus = 0.7", "taus", "unknown field"),
        ("[hesitaton]\nk_v = 0.3", "hesitaton", "unknown field"),
    ];
    for (text, key, rule) in cases {
        let msg = AssessConfig::from_toml_str(text).unwrap_err().to_string();
        assert!(
            msg.contains(key) && msg.contains(rule),
            "{text:?} gave: {msg}"
        );
    }
}
