#!/usr/bin/env python3
"""Mutation check of the assessment worked examples (issue 2 acceptance).

Applies one mutation at a time to a constant or formula of the model (assess::spec) in
assess/, runs the worked examples and the assess unit tests, reports whether some test failed
(CAUGHT) and restores the source. Run from the repository root:
python3 scripts/mutation-check.py (about 10 minutes).
Not part of CI: it rebuilds the crate once per mutation.
"""
import re
import subprocess
muts = [
 ("assess/src/config.rs", "head: 0.6,\n                body: 0.25,\n                hand: 0.15,", "head: 0.55,\n                body: 0.3,\n                hand: 0.15,", "nominal weights"),
 ("assess/src/config.rs", "head: 0.3,\n                body: 0.55,", "head: 0.35,\n                body: 0.5,", "turn weights"),
 ("assess/src/config.rs", "min_confidence: 0.3,", "min_confidence: 0.25,", "c_min"),
 ("assess/src/config.rs", "turn_yaw_rate_deg_s: 90.0,", "turn_yaw_rate_deg_s: 130.0,", "turn yaw rate"),
 ("assess/src/config.rs", "turn_lookback_frames: 3,", "turn_lookback_frames: 2,", "turn lookback"),
 ("assess/src/config.rs", "tau: 0.7,", "tau: 0.76,", "tau"),
 ("assess/src/config.rs", "Self { window_frames: 15 }", "Self { window_frames: 16 }", "M (default; examples set M)"),
 ("assess/src/config.rs", "max_frame_interval_s: 0.2,", "max_frame_interval_s: 0.25,", "dt_max"),
 ("assess/src/config.rs", "action_radius_m: 0.10,", "action_radius_m: 0.04,", "d_act"),
 ("assess/src/config.rs", "cost_high: 3.0,", "cost_high: 4.0,", "c_high"),
 ("assess/src/config.rs", "cost_int: 2.0,", "cost_int: 1.5,", "c_int"),
 ("assess/src/config.rs", "cost_base: 1.0,", "cost_base: 0.5,", "c_base"),
 ("assess/src/config.rs", "beta: 0.05,", "beta: 0.5,", "one-euro beta"),
 ("assess/src/config.rs", "k_v: 0.35,", "k_v: 0.4,", "k_v"),
 ("assess/src/config.rs", "v_min_m_s: 0.03,", "v_min_m_s: 0.02,", "v_min"),
 ("assess/src/config.rs", "v_max_m_s: 0.10,", "v_max_m_s: 0.12,", "v_max"),
 ("assess/src/config.rs", "median_horizon_s: 10.0,", "median_horizon_s: 1.5,", "median horizon"),
 ("assess/src/config.rs", "min_sample_time_s: 1.0,", "min_sample_time_s: 0.5,", "min sample time"),
 ("assess/src/config.rs", "min_duration_s: 0.3,", "min_duration_s: 0.25,", "t_min"),
 ("assess/src/config.rs", "epsilon_s: 1e-3,", "epsilon_s: 1e-2,", "epsilon"),
 ("assess/src/config.rs", "weights: ComponentValues::from_array([0.2; 5]),", "weights: ComponentValues::from_array([0.3, 0.1, 0.2, 0.2, 0.2]),", "composite weights"),
 ("assess/src/config.rs", "asd_ref_per_s: 0.5,", "asd_ref_per_s: 0.6,", "ASD_ref"),
 ("assess/src/config.rs", "medium_from: 0.33,", "medium_from: 0.335,", "category medium"),
 ("assess/src/config.rs", "high_from: 0.66,", "high_from: 0.65,", "category high"),
 ("assess/src/config.rs", "high_from: 0.66,", "high_from: 0.67,", "category high up"),
 ("assess/src/config.rs", "calibration_s: 60.0,", "calibration_s: 0.5,", "calibration period"),
 ("assess/src/config.rs", "baseline: ComponentValues::from_array([0.50, 0.15, 0.15, 0.20, 0.10]),", "baseline: ComponentValues::from_array([0.55, 0.15, 0.15, 0.20, 0.10]),", "default baseline"),
 ("assess/src/config.rs", "none_threshold: 0.01,", "none_threshold: 0.11,", "none threshold"),
 ("assess/src/config.rs", "hold_s: 3.0,", "hold_s: 2.5,", "T_dom"),
 ("assess/src/config.rs", "margin: 0.02,", "margin: 0.005,", "margin"),
 ("assess/src/evidence.rs", "(1.0 - distance_m / diagonal_m).max(0.0)", "(1.0 - distance_m / (1.1 * diagonal_m)).max(0.0)", "hand evidence normalisation"),
 ("assess/src/confirm.rs", "2 * c as usize > m", "2 * c as usize >= m", "strict majority"),
]
results = []
for path, old, new, name in muts:
    src = open(path).read()
    assert src.count(old) == 1, (name, src.count(old))
    open(path, 'w').write(src.replace(old, new))
    try:
        r = subprocess.run(["cargo", "test", "-q", "-p", "assess", "--test", "worked_examples", "--lib"], capture_output=True, text=True)
        out = r.stdout + r.stderr

        names = re.findall(r"^    ((?:s\d_|filter::|area::|hesitation::)\S+)$", out, re.M)
        results.append((name, r.returncode != 0, names))
    finally:
        open(path, 'w').write(src)
    print(f"{name:30s} {'CAUGHT' if results[-1][1] else 'missed'} {results[-1][2]}", flush=True)
