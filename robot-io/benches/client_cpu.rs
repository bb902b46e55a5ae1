//! The RTDE client's CPU time per second while it receives at 500 Hz from the emulator.
//!
//! The emulator (`--sim` backend: a SimRobot stepped in 2 ms cycles at real time) runs
//! in-process on its own tokio runtime (one worker thread) on ephemeral loopback ports. The
//! client runs on a separate runtime, so the threads measured are the client's only:
//!
//! - `current_thread`: one dedicated thread runs the client's supervisor, reader and writer
//!   tasks and the consumer;
//! - `multi_thread(2)`: the shape `hrc-adapt record` uses, two workers plus the thread that
//!   blocks on the consumer (all three measured).
//!
//! The client subscribes to a typical output recipe (timestamp, actual_q, actual_qd, target_q,
//! actual_TCP_pose, speed_scaling, robot_mode, safety_mode, runtime_state,
//! safety_status_bits) at 500 Hz and the consumer decodes every sample into caller-owned state
//! with precomputed slots (no allocation per sample). After 1 s of warm-up it streams for
//! `CLIENT_CPU_SECS` seconds (default 10).
//!
//! CPU time is each thread's on-CPU time from `/proc/self/task/<tid>/schedstat` (ns; falls
//! back to `stat` utime + stime in clock ticks), read at every 1 s window boundary. Printed:
//! client CPU ms per second of streaming (mean, median, p99, worst over the windows), the
//! emulator's for comparison, samples received against those expected by the controller
//! clock and by the wall clock, ring drops and timestamp gaps, the inter-arrival times, and
//! the receive latency. For the latency the client connects through a small relay on the
//! emulator's runtime that stamps each data package as it forwards it (keyed by its controller
//! timestamp); the latency runs from that stamp to the consumer holding the decoded sample, so
//! it covers one loopback hop, the client's reader task, its ring and the consumer's wake-up,
//! and not the emulator's own tick jitter. Linux only.

use std::sync::Arc;
use std::time::{Duration, Instant};

#[path = "common/mod.rs"]
mod common;
use common::{Stamps, Threads, current_tid, pct, relay, sorted, thread_cpu_ns};

use robot_io::client::{ClientConfig, OutputBuffer, RtdeClient};
use robot_io::codec::FieldSlot;
use robot_io::emulator::{CYCLE_S, Emulator, EmulatorConfig, SimBackend};
use robot_io::sim::{SimConfig, SimRobot};

const FIELDS: [&str; 10] = [
    "timestamp",
    "actual_q",
    "actual_qd",
    "target_q",
    "actual_TCP_pose",
    "speed_scaling",
    "robot_mode",
    "safety_mode",
    "runtime_state",
    "safety_status_bits",
];

/// Caller-owned state the consumer decodes each sample into.
#[derive(Debug, Default, Clone, Copy)]
struct State {
    timestamp_s: f64,
    actual_q: [f64; 6],
    actual_qd: [f64; 6],
    target_q: [f64; 6],
    actual_tcp_pose: [f64; 6],
    speed_scaling: f64,
    robot_mode: f64,
    safety_mode: f64,
    runtime_state: f64,
    safety_status_bits: f64,
}

/// Precomputed slots, in `FIELDS` order.
struct Slots([FieldSlot; 10]);

impl Slots {
    fn new(buf: &OutputBuffer) -> Slots {
        Slots(FIELDS.map(|n| buf.slot(n).expect("field in the recipe")))
    }

    fn decode(&self, buf: &OutputBuffer, s: &mut State) -> robot_io::Result<()> {
        let p = buf.payload();
        let [ts, q, qd, tq, pose, ss, rm, sm, rs, ssb] = &self.0;
        s.timestamp_s = ts.read_f64(p)?;
        q.read_into(p, &mut s.actual_q)?;
        qd.read_into(p, &mut s.actual_qd)?;
        tq.read_into(p, &mut s.target_q)?;
        pose.read_into(p, &mut s.actual_tcp_pose)?;
        s.speed_scaling = ss.read_f64(p)?;
        s.robot_mode = rm.read_f64(p)?;
        s.safety_mode = sm.read_f64(p)?;
        s.runtime_state = rs.read_f64(p)?;
        s.safety_status_bits = ssb.read_f64(p)?;
        Ok(())
    }
}

/// What one streaming run measured.
struct Run {
    /// Client CPU per 1 s window [ns].
    client_cpu_ns: Vec<u64>,
    /// Emulator CPU per 1 s window [ns].
    emulator_cpu_ns: Vec<u64>,
    /// Length of each window [s].
    window_s: Vec<f64>,
    /// Per sample: arrival [s since the start] and controller timestamp [s].
    arrivals: Vec<(f64, f64)>,
    /// Per sample: receive latency from the relay's forward [µs].
    latency_us: Vec<f64>,
    /// Samples the client's ring overwrote before the consumer read them.
    ring_drops: u64,
    /// Rejected packages (wrong recipe or length).
    rejected: u64,
}

async fn stream(
    port: u16,
    stamps: Arc<Stamps>,
    secs: u64,
    client_cpu: impl Fn() -> u64,
    emulator_cpu: impl Fn() -> u64,
) -> Run {
    let mut cfg = ClientConfig::new("127.0.0.1", &FIELDS);
    cfg.port = port;
    cfg.frequency_hz = 500.0;
    // A scheduling hiccup on a loaded host is not a link loss here.
    cfg.link_loss_min = Duration::from_secs(2);
    let mut client = RtdeClient::connect(cfg).await.expect("connect");
    let mut buf = client.output_buffer();
    let slots = Slots::new(&buf);
    let mut state = State::default();
    client.start().await.expect("start");
    // Warm-up: 1 s of samples, not measured.
    for _ in 0..500 {
        client
            .recv_timeout(&mut buf, Duration::from_secs(2))
            .await
            .expect("warm-up sample");
    }
    // Skip what queued up during the warm-up.
    while client.try_recv(&mut buf).expect("try_recv").is_some() {}
    let n_windows = usize::try_from(secs).expect("secs");
    let mut run = Run {
        client_cpu_ns: Vec::with_capacity(n_windows),
        emulator_cpu_ns: Vec::with_capacity(n_windows),
        window_s: Vec::with_capacity(n_windows),
        arrivals: Vec::with_capacity(n_windows * 600),
        latency_us: Vec::with_capacity(n_windows * 600),
        ring_drops: 0,
        rejected: client.rejected_packages(),
    };
    let t0 = Instant::now();
    let (mut c0, mut e0, mut w0) = (client_cpu(), emulator_cpu(), t0);
    while run.window_s.len() < n_windows {
        let info = client
            .recv_timeout(&mut buf, Duration::from_secs(2))
            .await
            .expect("sample");
        let now = Instant::now();
        slots.decode(&buf, &mut state).expect("decode");
        run.ring_drops += info.dropped;
        run.arrivals
            .push(((now - t0).as_secs_f64(), state.timestamp_s));
        if let Some(l) = stamps.latency_us(state.timestamp_s, now) {
            run.latency_us.push(l);
        }
        if now - w0 >= Duration::from_secs(1) {
            let (c1, e1) = (client_cpu(), emulator_cpu());
            run.client_cpu_ns.push(c1 - c0);
            run.emulator_cpu_ns.push(e1 - e0);
            run.window_s.push((now - w0).as_secs_f64());
            (c0, e0, w0) = (c1, e1, now);
        }
    }
    run.rejected = client.rejected_packages() - run.rejected;
    std::hint::black_box(state);
    client.close().await;
    run
}

fn report(name: &str, run: &Run) {
    let total_s: f64 = run.window_s.iter().sum();
    let per_s = |cpu: &[u64]| -> Vec<f64> {
        sorted(
            cpu.iter()
                .zip(&run.window_s)
                .map(|(ns, w)| *ns as f64 / 1e6 / w)
                .collect(),
        )
    };
    let client = per_s(&run.client_cpu_ns);
    let emu = per_s(&run.emulator_cpu_ns);
    let client_total_ms = run.client_cpu_ns.iter().sum::<u64>() as f64 / 1e6;
    let emu_total_ms = run.emulator_cpu_ns.iter().sum::<u64>() as f64 / 1e6;

    // Samples inside the measured windows.
    let end = run.window_s.iter().sum::<f64>();
    let inside: Vec<(f64, f64)> = run
        .arrivals
        .iter()
        .copied()
        .filter(|(t, _)| *t <= end)
        .collect();
    let received = inside.len();
    let (first_ts, last_ts) = (
        inside.first().map_or(0.0, |a| a.1),
        inside.last().map_or(0.0, |a| a.1),
    );
    let by_controller = ((last_ts - first_ts) / CYCLE_S).round() as usize + 1;
    let by_wall = (total_s * 500.0).round() as usize;
    let gaps = inside
        .windows(2)
        .filter(|w| w[1].1 - w[0].1 > 1.5 * CYCLE_S)
        .count();
    let inter = sorted(inside.windows(2).map(|w| (w[1].0 - w[0].0) * 1e3).collect());
    let latency = sorted(run.latency_us.clone());

    println!(
        "client_cpu/{name}: {total_s:.1} s streaming at 500 Hz, {} fields",
        FIELDS.len()
    );
    println!(
        "  client CPU [ms per s]: mean {:.2}, median {:.2}, p99 {:.2}, worst {:.2} over {} windows of 1 s ({:.1} µs per sample)",
        client_total_ms / total_s,
        pct(&client, 0.5),
        pct(&client, 0.99),
        client.last().copied().unwrap_or(f64::NAN),
        client.len(),
        client_total_ms * 1e3 / received.max(1) as f64,
    );
    println!(
        "  emulator CPU [ms per s] (own runtime, not in the above): mean {:.2}, worst {:.2}",
        emu_total_ms / total_s,
        emu.last().copied().unwrap_or(f64::NAN),
    );
    println!(
        "  samples: received {received}, expected {by_controller} by the controller clock, {by_wall} by the wall clock; ring drops {}, timestamp gaps {gaps}, rejected {}",
        run.ring_drops, run.rejected
    );
    println!(
        "  inter-arrival [ms]: median {:.3}, p99 {:.3}, worst {:.3}",
        pct(&inter, 0.5),
        pct(&inter, 0.99),
        inter.last().copied().unwrap_or(f64::NAN)
    );
    println!(
        "  receive latency [µs] (relay forward → decoded in the consumer, {} samples): median {:.0}, p99 {:.0}, worst {:.0}",
        latency.len(),
        pct(&latency, 0.5),
        pct(&latency, 0.99),
        latency.last().copied().unwrap_or(f64::NAN)
    );
}

fn main() {
    // `cargo bench` passes `--bench`; `cargo test --benches` passes nothing. An argument that
    // is not a flag filters by variant name, like criterion.
    let filter = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let secs: u64 = std::env::var("CLIENT_CPU_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10)
        .max(1);

    let emu_threads = Threads::default();
    let et = emu_threads.clone();
    let emu_rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("emulator")
        .on_thread_start(move || et.register())
        .enable_all()
        .build()
        .expect("emulator runtime");
    let emu = emu_rt.block_on(async {
        let robot = SimRobot::new(SimConfig::ur5e()).expect("sim");
        Emulator::start(
            EmulatorConfig::ephemeral(),
            Box::new(SimBackend::new(robot)),
        )
        .await
        .expect("emulator")
    });
    // The client connects through the stamping relay, which runs on the emulator's runtime.
    let stamps = Arc::new(Stamps::new());
    let port = emu_rt.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("relay bind");
        let port = listener.local_addr().expect("relay address").port();
        tokio::spawn(relay(listener, emu.rtde_addr(), stamps.clone()));
        port
    });
    let wanted = |name: &str| filter.as_deref().is_none_or(|f| name.contains(f));

    if wanted("current_thread") {
        let (et, st) = (emu_threads.clone(), stamps.clone());
        let run = std::thread::Builder::new()
            .name("client".into())
            .spawn(move || {
                let tid = current_tid();
                let rt = tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                    .expect("client runtime");
                rt.block_on(stream(
                    port,
                    st,
                    secs,
                    move || thread_cpu_ns(tid),
                    move || et.cpu_ns(),
                ))
            })
            .expect("client thread")
            .join()
            .expect("client run");
        report("current_thread", &run);
    }

    if wanted("multi_thread") {
        let client_threads = Threads::default();
        client_threads.register(); // this thread blocks on the consumer
        let ct = client_threads.clone();
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("client")
            .on_thread_start(move || ct.register())
            .enable_all()
            .build()
            .expect("client runtime");
        let (ct, et, st) = (client_threads.clone(), emu_threads.clone(), stamps.clone());
        let run = rt.block_on(async move {
            tokio::spawn(stream(
                port,
                st,
                secs,
                move || ct.cpu_ns(),
                move || et.cpu_ns(),
            ))
            .await
            .expect("consumer task")
        });
        report("multi_thread(2)", &run);
        rt.shutdown_timeout(Duration::from_secs(1));
    }
    drop(emu);
    emu_rt.shutdown_timeout(Duration::from_secs(1));
}
