//! The shipped rule table `config/policy-adaptive.toml` loads from disk, equals the embedded
//! copy, and documents every rule and every number.

use std::path::PathBuf;

use policies::{RuleTable, SHIPPED_TOML};

fn shipped_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../config/policy-adaptive.toml")
}

#[test]
fn the_shipped_file_loads_and_equals_the_embedded_table() {
    let from_disk = RuleTable::from_toml_file(shipped_path()).unwrap();
    assert_eq!(from_disk, RuleTable::shipped());
    assert_eq!(
        std::fs::read_to_string(shipped_path()).unwrap(),
        SHIPPED_TOML
    );
    let keys: Vec<&str> = from_disk.rules().iter().map(|r| r.key()).collect();
    assert_eq!(keys, ["none", "AED", "TID", "ICD", "ASD_ctx", "OHD"]);
    for r in from_disk.rules() {
        assert!(r.rationale().len() > 20, "{}: {}", r.key(), r.rationale());
        assert!(!r.rationale().contains('\n'), "{}: one line", r.key());
    }
}

#[test]
fn every_number_in_the_shipped_file_has_a_comment_above_it() {
    // Each `key = <number>` line must be preceded (directly, or through other numeric lines of
    // the same block) by a comment saying where the number comes from, except for the
    // identity values 0 and 1 of rules.none's scales, flags and disabled features, which the
    // header explains as the nominal baseline.
    let text = SHIPPED_TOML;
    let mut commented = false;
    for line in text.lines() {
        let l = line.trim();
        if l.starts_with('#') {
            commented = true;
            continue;
        }
        if l.is_empty() || l.starts_with('[') {
            commented = false;
            continue;
        }
        let Some((key, value)) = l.split_once('=') else {
            continue;
        };
        let value = value.trim();
        let Ok(x) = value.parse::<f64>() else {
            continue; // strings and booleans
        };
        if x == 0.0 || x == 1.0 {
            continue;
        }
        assert!(
            commented,
            "`{}` = {value} has no comment saying where it comes from",
            key.trim()
        );
    }
}
