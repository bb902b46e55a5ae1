//! Cross-check of rsruckig against the reference C++ Ruckig (PyPI `ruckig` 0.19.4).
//!
//! `tests/fixtures/ruckig_reference.csv` holds seeded random 6-DoF problems and the durations
//! the C++ library computed for them (written by `scripts/ruckig_reference.py`, which CI does
//! not run). Every problem must agree within 1e-9 relative.

#![allow(clippy::needless_range_loop)] // per-joint checks read clearer indexed

use std::collections::BTreeMap;

use adapt::otg::{MotionLimits, trajectory_duration};

const FIXTURE: &str = include_str!("fixtures/ruckig_reference.csv");
const REL_TOL: f64 = 1e-9;

type Joints = [f64; 6];

struct Problem {
    id: usize,
    class: String,
    fields: BTreeMap<String, Joints>,
    minimum_duration: Option<f64>,
    duration: f64,
}

fn parse() -> Vec<Problem> {
    let mut lines = FIXTURE.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let mut problems = Vec::new();
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells.len(), header.len(), "{line}");
        let mut fields = BTreeMap::new();
        for f in ["cp", "cv", "ca", "tp", "tv", "ta", "vmax", "amax", "jmax"] {
            let mut v = [0.0; 6];
            for (i, x) in v.iter_mut().enumerate() {
                *x = cells[col(&format!("{f}_{i}"))].parse().unwrap();
            }
            fields.insert(f.to_owned(), v);
        }
        let md = cells[col("minimum_duration")];
        problems.push(Problem {
            id: cells[col("id")].parse().unwrap(),
            class: cells[col("class")].to_owned(),
            fields,
            minimum_duration: (!md.is_empty()).then(|| md.parse().unwrap()),
            duration: cells[col("duration")].parse().unwrap(),
        });
    }
    problems
}

#[test]
fn rsruckig_durations_match_cpp_ruckig_within_1e_9_relative() {
    let problems = parse();
    assert!(problems.len() >= 1000, "only {} problems", problems.len());
    let mut worst = (0.0_f64, None);
    let mut identical = 0usize;
    let mut failures = Vec::new();
    let mut per_class: BTreeMap<String, (usize, f64)> = BTreeMap::new();
    for p in &problems {
        let f = |k: &str| &p.fields[k];
        let limits = MotionLimits::new(*f("vmax"), *f("amax"), *f("jmax")).unwrap();
        let got = trajectory_duration(
            [f("cp"), f("cv"), f("ca")],
            [f("tp"), f("tv"), f("ta")],
            &limits,
            p.minimum_duration,
        );
        match got {
            Ok(d) => {
                let rel = (d - p.duration).abs() / p.duration.abs().max(1e-12);
                let entry = per_class.entry(p.class.clone()).or_default();
                entry.0 += 1;
                entry.1 = entry.1.max(rel);
                if d == p.duration {
                    identical += 1;
                }
                if rel > worst.0 {
                    worst = (rel, Some(p.id));
                }
                if rel > REL_TOL {
                    failures.push(format!(
                        "problem {} ({}): rsruckig {d:.17} vs ruckig {:.17} (rel {rel:.3e})",
                        p.id, p.class, p.duration
                    ));
                }
            }
            Err(e) => failures.push(format!(
                "problem {} ({}): rsruckig error {e}",
                p.id, p.class
            )),
        }
    }
    eprintln!(
        "{} problems, {identical} bit-identical; max relative deviation {:.3e} (problem {:?}); \
         per class (count, max rel): {per_class:?}",
        problems.len(),
        worst.0,
        worst.1
    );
    assert!(
        failures.is_empty(),
        "{} of {} problems disagree:\n{}",
        failures.len(),
        problems.len(),
        failures.join("\n")
    );
}

// --- behaviour of the `Otg` wrapper ---

use hrc_adapt_tests::alloc_count::{CountingAllocator, allocations_in};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

use adapt::AdaptError;
use adapt::otg::{LimitScale, Otg, OtgState, PlanStatus, UR5E_CYCLE_S};

fn run_to_end(otg: &mut Otg, max_cycles: usize, mut each: impl FnMut(&OtgState)) -> usize {
    let mut out = OtgState::default();
    for cycle in 1..=max_cycles {
        let status = otg.step(&mut out).unwrap();
        each(&out);
        if status == PlanStatus::Finished {
            return cycle;
        }
    }
    panic!("not finished after {max_cycles} cycles");
}

#[test]
fn otg_reaches_the_target_within_its_limits() {
    let limits = MotionLimits::ur5e_nominal()
        .scaled(LimitScale::new(0.5).unwrap(), LimitScale::new(0.7).unwrap());
    let mut otg = Otg::new(UR5E_CYCLE_S, limits).unwrap();
    let start = [0.0, -1.57, 1.2, -1.0, -1.57, 0.0];
    otg.set_current_state(&start, &[0.0; 6], &[0.0; 6]).unwrap();
    let target = [0.8, -1.0, 0.6, -1.6, -1.2, 1.0];
    otg.set_target(&target, None).unwrap();
    let optimal = otg.time_optimal_duration().unwrap();
    let (v, a, j) = (
        limits.max_velocity()[0],
        limits.max_acceleration()[0],
        limits.max_jerk()[0],
    );
    let mut prev_a = [0.0; 6];
    let mut last = OtgState::default();
    let cycles = run_to_end(&mut otg, 10_000, |s| {
        for i in 0..6 {
            assert!(s.velocity[i].abs() <= v + 1e-9, "{s:?}");
            assert!(s.acceleration[i].abs() <= a + 1e-9, "{s:?}");
            assert!((s.acceleration[i] - prev_a[i]).abs() / UR5E_CYCLE_S <= j + 1e-6);
        }
        prev_a = s.acceleration;
        last = *s;
    });
    for (p, t) in last.position.iter().zip(&target) {
        assert!((p - t).abs() < 1e-9);
    }
    assert!(last.velocity.iter().all(|v| v.abs() < 1e-9));
    let elapsed = cycles as f64 * UR5E_CYCLE_S;
    assert!(
        (elapsed - optimal).abs() <= UR5E_CYCLE_S + 1e-12,
        "{elapsed} vs {optimal}"
    );
}

#[test]
fn otg_minimum_duration_stretches_the_motion() {
    let mut otg = Otg::new(UR5E_CYCLE_S, MotionLimits::ur5e_nominal()).unwrap();
    otg.set_current_state(&[0.0; 6], &[0.0; 6], &[0.0; 6])
        .unwrap();
    otg.set_target(&[0.3, 0.0, 0.0, 0.0, 0.0, 0.0], Some(3.0))
        .unwrap();
    let optimal = otg.time_optimal_duration().unwrap();
    assert!(optimal < 3.0);
    let cycles = run_to_end(&mut otg, 10_000, |_| {});
    let elapsed = cycles as f64 * UR5E_CYCLE_S;
    assert!((elapsed - 3.0).abs() <= UR5E_CYCLE_S + 1e-12, "{elapsed}");
}

#[test]
fn otg_retargets_online_continuously_and_without_allocating() {
    let mut otg = Otg::new(UR5E_CYCLE_S, MotionLimits::ur5e_nominal()).unwrap();
    otg.set_current_state(&[0.0; 6], &[0.0; 6], &[0.0; 6])
        .unwrap();
    otg.set_target(&[1.0, -0.5, 0.5, 0.2, -0.2, 0.7], None)
        .unwrap();
    let mut out = OtgState::default();
    let slow = MotionLimits::ur5e_nominal()
        .scaled(LimitScale::new(0.2).unwrap(), LimitScale::new(0.3).unwrap());
    let mut prev = OtgState::default();
    let ((), allocations) = allocations_in(|| {
        for cycle in 0..1500 {
            if cycle == 200 {
                otg.set_target(&[-0.5, 0.3, 0.0, 0.0, 0.4, -0.2], Some(1.5))
                    .unwrap();
            }
            if cycle == 400 {
                otg.set_limits(&slow);
            }
            if cycle == 700 {
                let _ = otg.time_optimal_duration().unwrap();
            }
            otg.step(&mut out).unwrap();
            if cycle > 0 {
                for i in 0..6 {
                    // Acceleration stays continuous across replans (jerk-limited).
                    assert!(
                        (out.acceleration[i] - prev.acceleration[i]).abs()
                            < 10.0 * std::f64::consts::PI * UR5E_CYCLE_S + 1e-9
                    );
                }
            }
            prev = out;
        }
    });
    assert_eq!(allocations, 0, "allocations in 1500 cycles with 3 replans");
}

#[test]
fn otg_rejects_bad_limits_scales_and_targets() {
    let nominal = [1.0; 6];
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let mut v = nominal;
        v[3] = bad;
        assert!(matches!(
            MotionLimits::new(v, nominal, nominal),
            Err(AdaptError::InvalidTrajectoryParameter { joint: 3, .. })
        ));
        assert!(MotionLimits::new(nominal, v, nominal).is_err());
        assert!(MotionLimits::new(nominal, nominal, v).is_err());
        assert!(LimitScale::new(bad).is_err());
    }
    assert!(LimitScale::new(1.5).is_err());
    assert!(Otg::new(0.0, MotionLimits::ur5e_nominal()).is_err());
    let mut otg = Otg::new(UR5E_CYCLE_S, MotionLimits::ur5e_nominal()).unwrap();
    assert!(
        otg.set_target(&[7.0, 0.0, 0.0, 0.0, 0.0, 0.0], None)
            .is_err()
    );
    assert!(otg.set_target(&[f64::NAN; 6], None).is_err());
    assert!(otg.set_target(&[0.0; 6], Some(-1.0)).is_err());
    assert!(
        otg.set_current_state(&[f64::NAN; 6], &[0.0; 6], &[0.0; 6])
            .is_err()
    );
}

#[test]
fn otg_without_target_holds_the_current_state() {
    let mut otg = Otg::new(UR5E_CYCLE_S, MotionLimits::ur5e_nominal()).unwrap();
    let q = [0.1, -1.0, 1.0, -1.5, -1.57, 0.2];
    otg.set_current_state(&q, &[0.0; 6], &[0.0; 6]).unwrap();
    let mut out = OtgState::default();
    assert_eq!(otg.step(&mut out).unwrap(), PlanStatus::Finished);
    assert_eq!(out.position, q);
}
