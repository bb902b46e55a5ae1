//! Benchmark of `Assessor::update` (one frame), for BENCHMARKS.md.
//!
//! Two measurements:
//! - criterion's estimate of the mean/median time per update (batched iterations);
//! - a per-call pass of 200 000 updates timed one by one with `Instant`, reporting the median,
//!   p99 and worst in ns, after subtracting the median cost of an empty `Instant` pair.
//!
//! Input: synthetic frames (simulated, not recorded) at 30 fps with every cue present, a
//! wandering gaze over four areas, a turning torso, two moving hands and collaboration periods.

use std::hint::black_box;
use std::time::Instant;

use assess::{
    AssessConfig, Assessor, BodyCue, CueFrame, HandCue, HeadCue, RobotContext, Vec3, Workspace,
};
use criterion::Criterion;

fn workspace() -> Workspace {
    let path = hrc_adapt_tests::config_dir().join("example-workspace.toml");
    Workspace::from_toml_file(path).expect("valid workspace")
}

/// Simulated frame number `k` (all cues present).
fn frame(k: u64) -> CueFrame {
    let phase = k as f64 * 0.05;
    let hand = |off: f64| {
        Some(HandCue {
            position: Vec3::new(0.5 + 0.2 * phase.sin() + off, 0.2 * phase.cos(), 0.8),
            confidence: 0.9,
        })
    };
    CueFrame {
        t: k as f64 / 30.0,
        head: Some(HeadCue {
            position: Vec3::new(0.0, 0.0, 1.5),
            facing: Vec3::new(phase.cos(), phase.sin(), -0.4),
            confidence: 0.95,
        }),
        body: Some(BodyCue {
            position: Vec3::new(0.0, 0.0, 1.3),
            facing: Vec3::new((phase * 0.3).cos(), (phase * 0.3).sin(), 0.0),
            confidence: 0.9,
        }),
        hands: [hand(0.0), hand(0.15)],
        robot: RobotContext {
            collaborating: (k / 90) % 2 == 1,
            incomplete: true,
        },
    }
}

fn percentile(sorted: &[u64], p: f64) -> u64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn per_call_pass() {
    // Precompute the frames so only `update` is timed.
    let frames: Vec<CueFrame> = (0..200_000).map(frame).collect();
    let mut a = Assessor::new(workspace(), AssessConfig::default()).expect("valid config");
    // Warm-up: fill the windows (30 s window, 10 s median, 60 s calibration).
    for f in &frames[..3_000] {
        black_box(a.update(f));
    }
    let mut overhead: Vec<u64> = (0..10_000)
        .map(|_| {
            let t0 = Instant::now();
            let t1 = Instant::now();
            (t1 - t0).as_nanos() as u64
        })
        .collect();
    overhead.sort_unstable();
    let timer = percentile(&overhead, 0.5);
    let mut ns: Vec<u64> = frames[3_000..]
        .iter()
        .map(|f| {
            let t0 = Instant::now();
            black_box(a.update(black_box(f)));
            (t0.elapsed().as_nanos() as u64).saturating_sub(timer)
        })
        .collect();
    ns.sort_unstable();
    println!(
        "assess/update per-call ({} calls, timer overhead {timer} ns subtracted): median {} ns, p99 {} ns, worst {} ns",
        ns.len(),
        percentile(&ns, 0.5),
        percentile(&ns, 0.99),
        ns[ns.len() - 1]
    );
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    let mut a = Assessor::new(workspace(), AssessConfig::default()).expect("valid config");
    let mut k = 0u64;
    for _ in 0..3_000 {
        a.update(&frame(k));
        k += 1;
    }
    // Frames are generated on the fly (times must increase); the generation is measured
    // separately and is part of the figure, so it is an upper bound on `update` alone.
    c.bench_function("assess/frame generation only", |b| {
        b.iter(|| {
            k += 1;
            black_box(frame(k))
        })
    });
    c.bench_function("assess/update (incl. frame generation)", |b| {
        b.iter(|| {
            k += 1;
            let f = frame(k);
            black_box(a.update(&f).cumulative.hrc_cwl)
        })
    });
    c.final_summary();
    per_call_pass();
}
