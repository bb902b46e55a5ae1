//! The native RTDE backend and the ur_rtde backend side by side, in one run on one emulator
//! (feature `ur-rtde`; issue 11, point 5). Linux only; figures go in BENCHMARKS.md and
//! nothing is asserted.
//!
//! The emulator (`SimBackend`, real time, a simulated UR5e) runs in-process on its own tokio
//! runtime (one worker) on 127.0.0.6 with UR's ports (ur_rtde's interfaces use 30004, 30003
//! and 29999 and cannot be pointed elsewhere). A stamping relay on 127.0.0.7:30004 forwards
//! its RTDE and notes when it wrote each data package (see `common`). Four phases, one after
//! the other:
//!
//! 1. **receive**: each backend's receive side at 500 Hz through the relay, the state fields
//!    of `RobotState`: the native [`RtdeRobot`] (our RTDE client on a 2-worker runtime, as
//!    `hrc-adapt trial` runs it) and ur_rtde's RTDEReceiveInterface ([`UrRtdeReceiver`]).
//!    - *CPU*: the consumer reads every 2 ms (absolute deadlines), as the control cycle
//!      does; CPU is the backend's threads plus the consumer's, from `schedstat`, per 1 s
//!      window (`BACKENDS_SECS`, default 10 windows);
//!    - *latency*: the consumer polls every 50 µs for `BACKENDS_SECS / 2` s; latency runs
//!      from the relay's write of a package to the consumer holding that sample (so it has
//!      up to ~50 µs of polling granularity on top of one loopback hop and the backend's
//!      own receive path).
//! 2. **control cycle**: read the state, send a servoJ target (joint 0 on a 0.05 rad, 0.2 Hz
//!    sine), at 500 Hz for `BACKENDS_SECS` s, directly on 127.0.0.6: the native `RtdeRobot`
//!    with our `hrc_control` program, paced on absolute 2 ms deadlines; then [`UrRtdeRobot`]
//!    with ur_rtde's control script, paced with its `initPeriod`/`waitPeriod`. Measured:
//!    the time inside `read_state` + `send` per cycle, the interval between cycle starts
//!    (a cycle is *late* when its start is over 1 ms after it was due), and CPU per second.

use std::collections::BTreeSet;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;
use std::time::{Duration, Instant};

#[path = "common/mod.rs"]
mod common;
use common::{Stamps, Threads, current_tid, pct, relay, sorted, thread_cpu_ns};

use robot_io::emulator::{Emulator, EmulatorConfig, SimBackend};
use robot_io::rtde_robot::{RtdeRobot, RtdeRobotConfig};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Robot, RobotState, UrRtdeConfig, UrRtdeReceiver, UrRtdeRobot};

const EMULATOR: Ipv4Addr = Ipv4Addr::new(127, 0, 0, 6);
const RELAY: Ipv4Addr = Ipv4Addr::new(127, 0, 0, 7);
const PERIOD: Duration = Duration::from_millis(2);

fn tids() -> BTreeSet<u32> {
    std::fs::read_dir("/proc/self/task")
        .expect("/proc/self/task (Linux)")
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse().ok())
        .collect()
}

fn cpu_of(t: &[u32]) -> u64 {
    t.iter().map(|&t| thread_cpu_ns(t)).sum()
}

fn line(name: &str, v: &[f64], unit: &str) {
    let v = sorted(v.to_vec());
    println!(
        "  {name} [{unit}]: median {:.2}, p99 {:.2}, worst {:.2} ({} values)",
        pct(&v, 0.5),
        pct(&v, 0.99),
        v.last().copied().unwrap_or(f64::NAN),
        v.len()
    );
}

/// Receive phase of one backend: CPU at the control pace, then latency with fast polling.
fn receive(
    name: &str,
    read: &mut dyn FnMut(&mut RobotState) -> robot_io::Result<()>,
    cpu: &dyn Fn() -> u64,
    stamps: &Stamps,
    secs: u64,
) {
    let mut s = RobotState::default();
    // Warm-up (1 s) until samples flow.
    let warm = Instant::now() + Duration::from_secs(1);
    while Instant::now() < warm {
        let _ = read(&mut s);
        std::thread::sleep(PERIOD);
    }
    let mut per_s = Vec::new();
    let (mut reads, mut new) = (0_u64, 0_u64);
    let mut due = Instant::now();
    for _ in 0..secs {
        let (c0, t0) = (cpu(), Instant::now());
        while t0.elapsed() < Duration::from_secs(1) {
            due += PERIOD;
            if let Some(d) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(d);
            }
            let last = s.timestamp_s;
            read(&mut s).expect("read");
            reads += 1;
            new += u64::from(s.timestamp_s != last);
        }
        per_s.push((cpu() - c0) as f64 / 1e6 / t0.elapsed().as_secs_f64());
    }
    let mut latency = Vec::new();
    let until = Instant::now() + Duration::from_secs(secs.div_ceil(2));
    while Instant::now() < until {
        let last = s.timestamp_s;
        read(&mut s).expect("read");
        if s.timestamp_s != last
            && let Some(l) = stamps.latency_us(s.timestamp_s, Instant::now())
        {
            latency.push(l);
        }
        std::thread::sleep(Duration::from_micros(50));
    }
    println!("receive/{name}: 500 Hz, {secs} s at the 2 ms control pace, then latency");
    line("CPU (backend threads + consumer)", &per_s, "ms per s");
    println!("  reads {reads}, new samples seen {new}");
    line(
        "latency (relay write → sample held by the consumer)",
        &latency,
        "µs",
    );
}

/// What one control-cycle run measured.
#[derive(Default)]
struct Cycles {
    work_us: Vec<f64>,
    interval_ms: Vec<f64>,
    late: u64,
    cpu_ms_per_s: Vec<f64>,
    errors: u64,
}

fn servo_target(q0: &[f64; 6], t_s: f64) -> JointCommand {
    let mut q = *q0;
    q[0] += 0.05 * (2.0 * std::f64::consts::PI * 0.2 * t_s).sin();
    JointCommand::Servo {
        q,
        lookahead_s: 0.1,
        gain: 300.0,
    }
}

fn report_cycles(name: &str, c: &Cycles) {
    println!("control/{name}: read_state + servoJ send at 500 Hz");
    line("read + send", &c.work_us, "µs");
    line("cycle interval", &c.interval_ms, "ms");
    println!(
        "  late cycles (start > 1 ms after due): {} of {}; send/read errors {}",
        c.late,
        c.interval_ms.len() + 1,
        c.errors
    );
    line(
        "CPU (backend threads + control thread)",
        &c.cpu_ms_per_s,
        "ms per s",
    );
}

fn main() {
    let secs: u64 = std::env::var("BACKENDS_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10)
        .max(2);
    let emu_threads = Threads::default();
    let et = emu_threads.clone();
    let emu_rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("emulator")
        .on_thread_start(move || et.register())
        .enable_all()
        .build()
        .expect("emulator runtime");
    let cfg = EmulatorConfig {
        bind: IpAddr::V4(EMULATOR),
        ..EmulatorConfig::default()
    };
    let emu = emu_rt
        .block_on(Emulator::start(
            cfg,
            Box::new(SimBackend::new(
                SimRobot::new(SimConfig::ur5e()).expect("sim"),
            )),
        ))
        .expect("emulator on 127.0.0.6 with UR's ports");
    let stamps = Arc::new(Stamps::new());
    emu_rt.block_on(async {
        let listener = tokio::net::TcpListener::bind(SocketAddr::new(IpAddr::V4(RELAY), 30004))
            .await
            .expect("relay on 127.0.0.7:30004");
        tokio::spawn(relay(listener, emu.rtde_addr(), stamps.clone()));
    });
    let emu_cpu0 = emu_threads.cpu_ns();
    let t_all = Instant::now();

    // --- receive, native ---
    {
        let threads = Threads::default();
        let ct = threads.clone();
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .on_thread_start(move || ct.register())
            .enable_all()
            .build()
            .expect("client runtime");
        let mut robot = rt
            .block_on(RtdeRobot::connect(RtdeRobotConfig::new(RELAY.to_string())))
            .expect("native connect");
        let me = current_tid();
        let cpu = || threads.cpu_ns() + thread_cpu_ns(me);
        receive(
            "native (RtdeRobot)",
            &mut |s| robot.read_state(s),
            &cpu,
            &stamps,
            secs,
        );
        drop(robot);
        rt.shutdown_timeout(Duration::from_secs(1));
    }

    // --- receive, ur_rtde ---
    {
        let before = tids();
        let mut rx = UrRtdeReceiver::connect(&UrRtdeConfig::new(RELAY.to_string()))
            .expect("ur_rtde receive connect");
        let mut measured: Vec<u32> = tids().difference(&before).copied().collect();
        let n = measured.len();
        measured.push(current_tid());
        let cpu = || cpu_of(&measured);
        receive(
            &format!("ur_rtde (RTDEReceiveInterface, {n} thread(s))"),
            &mut |s| rx.read(s),
            &cpu,
            &stamps,
            secs,
        );
    }

    // --- control cycle, native ---
    {
        let threads = Threads::default();
        let ct = threads.clone();
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .on_thread_start(move || ct.register())
            .enable_all()
            .build()
            .expect("client runtime");
        let mut cfg = RtdeRobotConfig::new(EMULATOR.to_string());
        cfg.program_port = Some(30003);
        let mut robot = rt
            .block_on(RtdeRobot::connect(cfg))
            .expect("native connect");
        rt.block_on(robot.start_program())
            .expect("hrc_control program");
        let me = current_tid();
        let cpu = || threads.cpu_ns() + thread_cpu_ns(me);
        let mut s = RobotState::default();
        rt.block_on(robot.wait_state(&mut s, Duration::from_secs(5)))
            .expect("first state");
        let q0 = s.actual_q;
        let mut c = Cycles::default();
        let start = Instant::now();
        let mut due = start;
        let mut last_start: Option<Instant> = None;
        for _ in 0..secs {
            let (c0, w0) = (cpu(), Instant::now());
            while w0.elapsed() < Duration::from_secs(1) {
                due += PERIOD;
                if let Some(d) = due.checked_duration_since(Instant::now()) {
                    std::thread::sleep(d);
                }
                let t = Instant::now();
                if t.duration_since(due) > Duration::from_millis(1) {
                    c.late += 1;
                }
                if let Some(l) = last_start {
                    c.interval_ms.push((t - l).as_secs_f64() * 1e3);
                }
                last_start = Some(t);
                let ok = robot.read_state(&mut s).is_ok()
                    && robot
                        .send(&servo_target(&q0, (t - start).as_secs_f64()))
                        .is_ok();
                c.errors += u64::from(!ok);
                c.work_us.push(t.elapsed().as_secs_f64() * 1e6);
            }
            c.cpu_ms_per_s
                .push((cpu() - c0) as f64 / 1e6 / w0.elapsed().as_secs_f64());
        }
        report_cycles("native (RtdeRobot, hrc_control)", &c);
        drop(robot);
        rt.shutdown_timeout(Duration::from_secs(1));
    }

    // --- control cycle, ur_rtde ---
    {
        let before = tids();
        let mut robot = UrRtdeRobot::connect(&UrRtdeConfig::new(EMULATOR.to_string()))
            .expect("ur_rtde connect (the emulator runs ur_rtde's control script)");
        let mut measured: Vec<u32> = tids().difference(&before).copied().collect();
        measured.push(current_tid());
        let mut s = RobotState::default();
        let first = Instant::now() + Duration::from_secs(5);
        while robot.read_state(&mut s).is_err() || s.timestamp_s == 0.0 {
            assert!(Instant::now() < first, "no state from ur_rtde");
            std::thread::sleep(PERIOD);
        }
        let q0 = s.actual_q;
        let mut c = Cycles::default();
        let start = Instant::now();
        let mut last_start: Option<Instant> = None;
        for _ in 0..secs {
            let (c0, w0) = (cpu_of(&measured), Instant::now());
            while w0.elapsed() < Duration::from_secs(1) {
                let t_ns = robot.init_period().expect("initPeriod");
                let t = Instant::now();
                if let Some(l) = last_start {
                    let interval = t - l;
                    if interval > PERIOD + Duration::from_millis(1) {
                        c.late += 1;
                    }
                    c.interval_ms.push(interval.as_secs_f64() * 1e3);
                }
                last_start = Some(t);
                let ok = robot.read_state(&mut s).is_ok()
                    && robot
                        .send(&servo_target(&q0, (t - start).as_secs_f64()))
                        .is_ok();
                c.errors += u64::from(!ok);
                c.work_us.push(t.elapsed().as_secs_f64() * 1e6);
                robot.wait_period(t_ns).expect("waitPeriod");
            }
            c.cpu_ms_per_s
                .push((cpu_of(&measured) - c0) as f64 / 1e6 / w0.elapsed().as_secs_f64());
        }
        report_cycles("ur_rtde (UrRtdeRobot, ur_rtde's control script)", &c);
        // `send` hands over; ur_rtde's sender thread makes the call (counted above, as one of
        // the threads ur_rtde's connect started). What it did with the commands:
        println!("  ur_rtde sender thread: {:?}", robot.send_stats());
        drop(robot);
    }
    println!(
        "emulator CPU over the run: {:.2} ms per s",
        (emu_threads.cpu_ns() - emu_cpu0) as f64 / 1e6 / t_all.elapsed().as_secs_f64()
    );
    drop(emu);
    emu_rt.shutdown_timeout(Duration::from_secs(1));
}
