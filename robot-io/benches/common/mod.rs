//! Helpers the `client_cpu` and `backends` benches share (each includes this file with
//! `#[path]`): per-thread CPU time from `/proc`, a stamping RTDE relay for receive latency, and
//! quantiles. Linux only.

#![allow(dead_code)]

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use robot_io::emulator::CYCLE_S;

/// When the relay forwarded the data package of each controller cycle (a ring by cycle).
pub(crate) struct Stamps {
    t0: Instant,
    /// Nanoseconds since `t0` plus one (0: none yet), at index `cycle % len`.
    ns: Vec<AtomicU64>,
}

impl Stamps {
    pub(crate) fn new() -> Stamps {
        Stamps {
            t0: Instant::now(),
            ns: (0..8192).map(|_| AtomicU64::new(0)).collect(),
        }
    }

    fn cycle(timestamp_s: f64) -> usize {
        (timestamp_s / CYCLE_S).round() as usize
    }

    pub(crate) fn stamp(&self, timestamp_s: f64) {
        let ns = u64::try_from(self.t0.elapsed().as_nanos()).unwrap_or(u64::MAX);
        let k = Stamps::cycle(timestamp_s) % self.ns.len();
        self.ns[k].store(ns + 1, Ordering::Release);
    }

    /// Latency from the forward of the package at `timestamp_s` to `now` [µs].
    pub(crate) fn latency_us(&self, timestamp_s: f64, now: Instant) -> Option<f64> {
        let k = Stamps::cycle(timestamp_s) % self.ns.len();
        let ns = self.ns[k].load(Ordering::Acquire).checked_sub(1)?;
        let sent = self.t0 + Duration::from_nanos(ns);
        Some(now.saturating_duration_since(sent).as_secs_f64() * 1e6)
    }
}

/// Forwards RTDE between the client and the emulator, stamping controller-to-client data
/// packages (whose recipe starts with `timestamp`) as it writes them.
pub(crate) async fn relay(
    listener: tokio::net::TcpListener,
    upstream: SocketAddr,
    stamps: Arc<Stamps>,
) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    while let Ok((down, _)) = listener.accept().await {
        let stamps = stamps.clone();
        tokio::spawn(async move {
            let Ok(up) = tokio::net::TcpStream::connect(upstream).await else {
                return;
            };
            let _ = (up.set_nodelay(true), down.set_nodelay(true));
            let (mut ur, mut uw) = up.into_split();
            let (mut dr, mut dw) = down.into_split();
            let upward = tokio::spawn(async move {
                let _ = tokio::io::copy(&mut dr, &mut uw).await;
            });
            let mut buf = vec![0u8; 1 << 16];
            loop {
                if ur.read_exact(&mut buf[..2]).await.is_err() {
                    break;
                }
                let size = usize::from(u16::from_be_bytes([buf[0], buf[1]])).max(3);
                if ur.read_exact(&mut buf[2..size]).await.is_err() {
                    break;
                }
                let ts = (buf[2] == b'U' && size >= 12)
                    .then(|| f64::from_be_bytes(buf[4..12].try_into().unwrap_or_default()));
                if let Some(ts) = ts {
                    stamps.stamp(ts);
                }
                if dw.write_all(&buf[..size]).await.is_err() {
                    break;
                }
            }
            upward.abort();
        });
    }
}

/// The calling thread's id (from `/proc/thread-self`, which links to `<pid>/task/<tid>`).
pub(crate) fn current_tid() -> u32 {
    std::fs::read_link("/proc/thread-self")
        .ok()
        .and_then(|p| p.file_name()?.to_str()?.parse().ok())
        .expect("/proc/thread-self (Linux)")
}

/// On-CPU time of thread `tid` of this process [ns].
pub(crate) fn thread_cpu_ns(tid: u32) -> u64 {
    let sched = std::fs::read_to_string(format!("/proc/self/task/{tid}/schedstat"));
    if let Some(ns) = sched
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
    {
        return ns;
    }
    // Fallback: utime + stime [clock ticks of 10 ms], fields 14 and 15 of `stat` (tokens 11
    // and 12 after the parenthesised `comm`, which may contain spaces).
    let stat = std::fs::read_to_string(format!("/proc/self/task/{tid}/stat")).unwrap_or_default();
    let after_comm = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let ticks = |k: usize| -> u64 {
        after_comm
            .split_whitespace()
            .nth(k)
            .and_then(|x| x.parse().ok())
            .unwrap_or(0)
    };
    (ticks(11) + ticks(12)) * 10_000_000
}

/// Threads registered by a runtime's `on_thread_start`.
#[derive(Clone, Default)]
pub(crate) struct Threads(Arc<Mutex<Vec<u32>>>);

impl Threads {
    pub(crate) fn register(&self) {
        self.0.lock().expect("lock").push(current_tid());
    }

    pub(crate) fn cpu_ns(&self) -> u64 {
        self.0
            .lock()
            .expect("lock")
            .iter()
            .map(|t| thread_cpu_ns(*t))
            .sum()
    }
}

/// Value at quantile `q` of sorted `v`.
pub(crate) fn pct(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v[((v.len() - 1) as f64 * q).round() as usize]
}

pub(crate) fn sorted(mut v: Vec<f64>) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    v
}
