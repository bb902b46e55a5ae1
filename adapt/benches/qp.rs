//! QP speed scaling per cycle: the allocation-free `SpeedScaler` and the clarabel cross-check,
//! on three cases (no active row, separation rows active and feasible, infeasible → slack).
//! Criterion gives the median; a plain `Instant` loop prints p99 and worst (criterion does not).

use std::hint::black_box;
use std::time::{Duration, Instant};

use adapt::qp::{
    ClarabelSpeedScaler, ControlPointInput, HumanPoint, QpConfig, QpInput, SpeedScaler,
};
use adapt::ssm::HumanPointKind;
use criterion::{Criterion, criterion_group, criterion_main};

fn cases() -> [(&'static str, QpInput); 3] {
    let tcp = ControlPointInput {
        position: [0.0; 3],
        jacobian: [
            [-0.3, 0.1, 0.05, 0.2, 0.0, 0.0],
            [0.6, 0.0, 0.3, 0.0, 0.1, 0.0],
            [0.0, 0.5, 0.4, 0.1, 0.08, 0.0],
        ],
    };
    let mut wrist = tcp;
    wrist.position = [-0.1, 0.0, 0.0];
    wrist.jacobian[0][3] = 0.0;
    let mut elbow = tcp;
    elbow.position = [-0.4, 0.0, 0.1];
    elbow.jacobian = [
        [0.5, 0.2, 0.0, 0.0, 0.0, 0.0],
        [0.0, 0.4, 0.0, 0.0, 0.0, 0.0],
        [0.0; 6],
    ];
    let free = QpInput {
        qd_ref: [0.8, 0.6, 0.2, 0.2, 0.0, 0.1],
        qd_prev: [0.8, 0.6, 0.2, 0.2, 0.0, 0.1],
        dt_s: 0.002,
        max_velocity: [std::f64::consts::PI; 6],
        max_acceleration: [std::f64::consts::PI; 6],
        tcp_speed_cap_m_s: 1.0,
        control_points: [tcp, wrist, elbow],
        humans: [None; 3],
    };
    let mut near = free;
    near.humans = [
        Some(HumanPoint {
            position: [0.3, 0.6, 0.9],
            kind: HumanPointKind::Head,
        }),
        Some(HumanPoint {
            position: [0.1, 0.75, 0.3],
            kind: HumanPointKind::Hand,
        }),
        Some(HumanPoint {
            position: [-0.2, 0.7, 0.4],
            kind: HumanPointKind::Hand,
        }),
    ];
    near.max_acceleration = [400.0; 6];
    let mut slack = near;
    slack.max_acceleration = [std::f64::consts::PI; 6];
    [("free", free), ("separation", near), ("slack", slack)]
}

fn tails(name: &str, mut f: impl FnMut()) {
    const N: usize = 20_000;
    let mut t = Vec::with_capacity(N);
    for _ in 0..N {
        let s = Instant::now();
        f();
        t.push(s.elapsed());
    }
    t.sort_unstable();
    let q = |p: f64| t[((N as f64 * p) as usize).min(N - 1)];
    let us = |d: Duration| d.as_secs_f64() * 1e6;
    println!(
        "{name:<32} median {:8.2} µs   p99 {:8.2} µs   worst {:8.2} µs   (n = {N})",
        us(q(0.5)),
        us(q(0.99)),
        us(t[N - 1])
    );
}

fn bench(c: &mut Criterion) {
    let mut ours = SpeedScaler::new(QpConfig::default()).unwrap();
    let mut cla = ClarabelSpeedScaler::new(QpConfig::default()).unwrap();
    let mut out = [0.0; 6];
    for (name, input) in cases() {
        let st = ours.solve(&input, &mut out);
        let rows = ours.report().rows;
        let sweeps = ours.report().sweeps;
        let st_c = cla.solve(&input, &mut out);
        println!("case {name}: rows {rows}, ours {st:?} ({sweeps} sweeps), clarabel {st_c:?}");
        tails(&format!("speed_scaler/{name}"), || {
            black_box(ours.solve(black_box(&input), &mut out));
        });
        tails(&format!("clarabel/{name}"), || {
            black_box(cla.solve(black_box(&input), &mut out));
        });
        c.bench_function(&format!("speed_scaler/{name}"), |b| {
            b.iter(|| ours.solve(black_box(&input), &mut out))
        });
        c.bench_function(&format!("clarabel/{name}"), |b| {
            b.iter(|| cla.solve(black_box(&input), &mut out))
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
