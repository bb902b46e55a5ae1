//! Agreement with scipy on the committed fixture `scipy_reference.json`, written by
//! `scripts/stats_reference.py` (scipy, numpy and statsmodels versions are recorded in it).
//!
//! Tolerances, and why:
//! * **bit-for-bit** where scipy's answer is exact arithmetic on small integers: the Wilcoxon
//!   statistic and rank-biserial correlation (rank sums are half-integers), exact and sign-flip
//!   permutation p-values (counts over 2ⁿ: dyadic rationals, exact in `f64`), the exact Spearman
//!   permutation p-value (one correctly rounded division count/n!), Holm's adjusted p-values (the
//!   same products, min and max as numpy/statsmodels).
//! * **1e-12 relative** for statistics summed in a different order (Friedman χ², Kendall's W,
//!   Spearman ρ): a few ulps of rounding, nothing more.
//! * **1e-10 relative** for p-values from continuous distributions (normal, χ², Student t): our
//!   Numerical Recipes kernels and scipy's Cephes/Boost kernels are each good to ~1e-14 relative,
//!   and the statistic's own rounding is amplified by at most |d log p / d stat| ≈ stat (< 40
//!   here) — far below 1e-10, which still catches any real formula difference (a wrong tie or
//!   continuity correction moves p by more than 1e-4).

use serde_json::Value;

use super::*;

const FIXTURE: &str = include_str!("scipy_reference.json");

fn fixture() -> Value {
    serde_json::from_str(FIXTURE).expect("scipy_reference.json parses")
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

/// The expected value of a `{"value", "bits"}` pair, from its exact bit pattern.
fn expected(v: &Value) -> f64 {
    f64::from_bits(v["bits"].as_u64().expect("bits"))
}

fn rel_err(got: f64, want: f64) -> f64 {
    if got == want {
        0.0
    } else {
        (got - want).abs() / want.abs().max(f64::MIN_POSITIVE)
    }
}

/// Asserts `got` within `rel` of `want` and returns the relative error (for the summary line).
fn check(name: &str, what: &str, got: f64, want: f64, rel: f64) -> f64 {
    let e = rel_err(got, want);
    assert!(
        e <= rel,
        "{name}: {what} {got:e} vs scipy {want:e} (relative error {e:e} > {rel:e})"
    );
    e
}

fn check_bits(name: &str, what: &str, got: f64, want: f64) {
    assert_eq!(
        got.to_bits(),
        want.to_bits(),
        "{name}: {what} {got:e} vs scipy {want:e} (bit-for-bit)"
    );
}

/// The versions the fixture was made with are recorded (and shown with `--nocapture`).
#[test]
fn fixture_records_versions() {
    let f = fixture();
    for key in ["scipy", "numpy"] {
        assert!(
            f["versions"][key].is_string(),
            "fixture lacks the {key} version"
        );
    }
    println!("fixture from {}", f["versions"]);
}

#[test]
fn wilcoxon_matches_scipy() {
    let f = fixture();
    let cases = f["wilcoxon"].as_array().unwrap();
    assert!(cases.len() >= 150);
    let mut worst = 0.0_f64;
    let mut methods = [0_usize; 3];
    for c in cases {
        let name = c["name"].as_str().unwrap();
        let zero_method = match c["zero_method"].as_str().unwrap() {
            "wilcox" => ZeroMethod::Wilcox,
            "pratt" => ZeroMethod::Pratt,
            "zsplit" => ZeroMethod::Zsplit,
            other => panic!("{name}: zero_method {other}"),
        };
        let method = match c["method"].as_str().unwrap() {
            "auto" => WilcoxonMethod::Auto,
            "asymptotic" => WilcoxonMethod::Asymptotic,
            other => panic!("{name}: method {other}"),
        };
        let options = WilcoxonOptions {
            zero_method,
            correction: c["correction"].as_bool().unwrap(),
            method,
        };
        let r = wilcoxon(&floats(&c["x"]), &floats(&c["y"]), options).unwrap();
        let used = match c["method_used"].as_str().unwrap() {
            "exact" => WilcoxonMethod::Exact,
            "permutation" => WilcoxonMethod::Permutation,
            "asymptotic" => WilcoxonMethod::Asymptotic,
            other => panic!("{name}: method_used {other}"),
        };
        assert_eq!(r.method, used, "{name}: method chosen");
        check_bits(name, "statistic", r.statistic, expected(&c["statistic"]));
        check_bits(
            name,
            "rank-biserial",
            r.rank_biserial,
            expected(&c["rank_biserial"]),
        );
        let want_p = expected(&c["pvalue"]);
        match used {
            WilcoxonMethod::Asymptotic => {
                worst = worst.max(check(name, "p", r.p_value, want_p, 1e-10));
                methods[2] += 1;
            }
            _ => {
                check_bits(name, "p", r.p_value, want_p);
                methods[usize::from(used == WilcoxonMethod::Permutation)] += 1;
            }
        }
    }
    println!(
        "wilcoxon: {} cases ({} exact, {} permutation, {} normal); worst normal p error {worst:e}",
        cases.len(),
        methods[0],
        methods[1],
        methods[2]
    );
}

#[test]
fn friedman_matches_scipy() {
    let f = fixture();
    let cases = f["friedman"].as_array().unwrap();
    assert!(cases.len() >= 20);
    let (mut worst_stat, mut worst_p) = (0.0_f64, 0.0_f64);
    for c in cases {
        let name = c["name"].as_str().unwrap();
        let blocks: Vec<Vec<f64>> = c["blocks"].as_array().unwrap().iter().map(floats).collect();
        let r = friedman(&blocks).unwrap();
        worst_stat = worst_stat.max(check(
            name,
            "χ²",
            r.statistic,
            expected(&c["statistic"]),
            1e-12,
        ));
        check(
            name,
            "Kendall's W",
            r.kendall_w,
            expected(&c["kendall_w"]),
            1e-12,
        );
        worst_p = worst_p.max(check(name, "p", r.p_value, expected(&c["pvalue"]), 1e-10));
        assert_eq!(r.df, blocks[0].len() - 1);
    }
    println!(
        "friedman: {} cases; worst χ² error {worst_stat:e}, worst p error {worst_p:e}",
        cases.len()
    );
}

#[test]
fn holm_matches_statsmodels() {
    let f = fixture();
    let cases = f["holm"].as_array().unwrap();
    assert!(cases.len() >= 10);
    for c in cases {
        let name = c["name"].as_str().unwrap();
        let got = holm(&floats(&c["p"])).unwrap();
        let want: Vec<f64> = c["adjusted"]
            .as_array()
            .unwrap()
            .iter()
            .map(expected)
            .collect();
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(&want) {
            check_bits(name, "adjusted p", *g, *w);
        }
    }
}

#[test]
fn spearman_matches_scipy() {
    let f = fixture();
    let cases = f["spearman"].as_array().unwrap();
    assert!(cases.len() >= 15);
    let (mut worst_rho, mut worst_p, mut exact) = (0.0_f64, 0.0_f64, 0);
    for c in cases {
        let name = c["name"].as_str().unwrap();
        let (x, y) = (floats(&c["x"]), floats(&c["y"]));
        let t = spearman(&x, &y, SpearmanMethod::TApproximation).unwrap();
        worst_rho = worst_rho.max(check(name, "ρ", t.rho, expected(&c["rho"]), 1e-12));
        worst_p = worst_p.max(check(
            name,
            "t p",
            t.p_value,
            expected(&c["pvalue_t"]),
            1e-10,
        ));
        if !c["pvalue_exact"].is_null() {
            let e = spearman(&x, &y, SpearmanMethod::ExactPermutation).unwrap();
            check_bits(name, "exact p", e.p_value, expected(&c["pvalue_exact"]));
            exact += 1;
        }
    }
    println!(
        "spearman: {} cases ({exact} exact); worst ρ error {worst_rho:e}, worst t p error {worst_p:e}",
        cases.len()
    );
}
