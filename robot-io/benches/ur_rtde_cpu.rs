//! ur_rtde's RTDEReceiveInterface (feature `ur-rtde`, through our shim) receiving at 500 Hz
//! from the in-process emulator (`SimBackend`, real time, on 127.0.0.2 with ur_rtde's fixed
//! port 30004): CPU time per second of the receive side, and how many new samples a consumer
//! polling every 2 ms saw.
//!
//! The threads measured are those that appear in `/proc/self/task` when the receive interface
//! is built (ur_rtde's receive thread) plus the consumer (this thread). CPU time is each
//! thread's on-CPU time from `schedstat` [ns]. After 1 s of warm-up it streams for
//! `CLIENT_CPU_SECS` seconds (default 10). Linux only. Figures go in BENCHMARKS.md; nothing is
//! asserted.

use std::collections::BTreeSet;
use std::net::{IpAddr, Ipv4Addr};
use std::time::{Duration, Instant};

use robot_io::emulator::{Emulator, EmulatorConfig, SimBackend};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{RobotState, UrRtdeConfig, UrRtdeReceiver};

fn tids() -> BTreeSet<u32> {
    std::fs::read_dir("/proc/self/task")
        .expect("/proc/self/task (Linux)")
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse().ok())
        .collect()
}

fn current_tid() -> u32 {
    std::fs::read_link("/proc/thread-self")
        .ok()
        .and_then(|p| p.file_name()?.to_str()?.parse().ok())
        .expect("/proc/thread-self (Linux)")
}

fn thread_cpu_ns(tid: u32) -> u64 {
    std::fs::read_to_string(format!("/proc/self/task/{tid}/schedstat"))
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
}

fn pct(v: &[f64], q: f64) -> f64 {
    let i = ((v.len() - 1) as f64 * q).round() as usize;
    v[i]
}

/// Reads every 2 ms until `until`, counting reads and new timestamps.
fn poll(
    rx: &mut UrRtdeReceiver,
    s: &mut RobotState,
    until: Instant,
    new: &mut u64,
    polls: &mut u64,
) {
    while Instant::now() < until {
        let last_ts = s.timestamp_s;
        rx.read(s).unwrap();
        *polls += 1;
        if s.timestamp_s != last_ts {
            *new += 1;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

fn main() {
    let secs: u64 = std::env::var("CLIENT_CPU_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let cfg = EmulatorConfig {
        bind: IpAddr::V4(Ipv4Addr::new(127, 0, 0, 2)),
        rtde_port: 30004,
        dashboard_port: 0,
        secondary_port: 0,
        realtime_port: 0,
        ..EmulatorConfig::default()
    };
    let robot = SimRobot::new(SimConfig::ur5e()).unwrap();
    let emu = rt
        .block_on(Emulator::start(cfg, Box::new(SimBackend::new(robot))))
        .unwrap();
    let before = tids();
    let mut rx = UrRtdeReceiver::connect(&UrRtdeConfig::new("127.0.0.2")).unwrap();
    let mut measured: Vec<u32> = tids().difference(&before).copied().collect();
    let ur_threads = measured.len();
    measured.push(current_tid());
    let cpu = |m: &[u32]| m.iter().map(|&t| thread_cpu_ns(t)).sum::<u64>();

    let mut s = RobotState::default();
    let (mut new, mut polls) = (0, 0);
    poll(
        &mut rx,
        &mut s,
        Instant::now() + Duration::from_secs(1),
        &mut new,
        &mut polls,
    );
    let mut per_s = Vec::new();
    let (mut new, mut polls) = (0_u64, 0_u64);
    let ts0 = s.timestamp_s;
    for _ in 0..secs {
        let c0 = cpu(&measured);
        let t0 = Instant::now();
        poll(
            &mut rx,
            &mut s,
            t0 + Duration::from_secs(1),
            &mut new,
            &mut polls,
        );
        let c1 = cpu(&measured);
        per_s.push((c1 - c0) as f64 / 1e6 / t0.elapsed().as_secs_f64());
    }
    let controller_s = s.timestamp_s - ts0;
    let mean = per_s.iter().sum::<f64>() / per_s.len() as f64;
    let mut sorted = per_s.clone();
    sorted.sort_by(f64::total_cmp);
    println!(
        "ur_rtde receive (RTDEReceiveInterface via the shim, {ur_threads} ur_rtde thread(s) + the consumer), 500 Hz, {secs} s:"
    );
    println!(
        "  CPU ms/s: mean {mean:.2}, median {:.2}, p99 {:.2}, worst {:.2}",
        pct(&sorted, 0.5),
        pct(&sorted, 0.99),
        sorted[sorted.len() - 1]
    );
    println!(
        "  consumer polls {polls}, new samples seen {new}, controller time {controller_s:.3} s ({} samples at 500 Hz)",
        (controller_s * 500.0).round()
    );
    drop(rx);
    emu.shutdown();
}
