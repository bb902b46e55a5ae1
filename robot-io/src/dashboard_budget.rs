//! The dashboard server's defences against clients that flood it (issue 11, hostile clients).
//!
//! A PolyScope dashboard client sends one command and waits for its reply. A client that sends
//! its next line before it has read the reply to the last one is **pipelining**: harmless at a
//! few lines, but a client streaming garbage pipelines hundreds of thousands of lines a second,
//! and every one of them costs the emulator a reply. Two bounds keep such clients from taking
//! the CPU that a well-behaved client's round trips need:
//!
//! - [`LineBudget`]: one token bucket **shared by every dashboard connection**, spent only by
//!   pipelined lines. A request/reply client never pipelines, so it never waits for it; a
//!   flooding client waits, stops reading its socket, and TCP's flow control stops it sending.
//!   The bucket is shared because a per-connection budget is no bound at all against a client
//!   that reconnects (tried in session 11, BENCHMARKS.md "The emulator under hostile clients").
//! - [`MAX_DASHBOARD_CONNECTIONS`]: open dashboard connections at most; one over it is told so
//!   and closed.
//!
//! [`LineBudget::take`] is a pure function of the time it is given, so its arithmetic is
//! tested on a scripted clock (`line_budget_worked_example`).

use std::time::{Duration, Instant};

/// Pipelined dashboard lines served per second, summed over all connections [1/s].
///
/// A request/reply client is never limited by it. 2 000 lines/s is far more than any
/// dashboard client needs (ur_rtde's `DashboardClient` and PolyScope's own tools wait for each
/// reply) and a few percent of what the emulator answers when it does nothing else.
pub const PIPELINED_LINES_PER_S: f64 = 2000.0;

/// Pipelined lines that may be served at once before the rate applies [-].
pub const PIPELINED_BURST: f64 = 200.0;

/// Open dashboard connections at most [-]; the next one is told so and closed.
pub const MAX_DASHBOARD_CONNECTIONS: usize = 64;

/// A token bucket: `rate` tokens a second, at most `burst` kept.
#[derive(Debug, Clone)]
pub struct LineBudget {
    rate_per_s: f64,
    burst: f64,
    tokens: f64,
    last: Option<Instant>,
}

impl Default for LineBudget {
    fn default() -> Self {
        Self::new(PIPELINED_LINES_PER_S, PIPELINED_BURST)
    }
}

impl LineBudget {
    /// A full bucket refilled at `rate_per_s` [1/s], holding at most `burst` [-] tokens.
    /// Non-finite or non-positive values are raised to one token a second and one token.
    pub fn new(rate_per_s: f64, burst: f64) -> Self {
        let rate_per_s = if rate_per_s.is_finite() && rate_per_s > 0.0 {
            rate_per_s
        } else {
            1.0
        };
        let burst = if burst.is_finite() && burst >= 1.0 {
            burst
        } else {
            1.0
        };
        Self {
            rate_per_s,
            burst,
            tokens: burst,
            last: None,
        }
    }

    /// Takes one token at `now`: `None` when taken, else how long until one is there (the
    /// caller waits that long and asks again; nothing is taken meanwhile).
    pub fn take(&mut self, now: Instant) -> Option<Duration> {
        if let Some(last) = self.last {
            let dt = now.saturating_duration_since(last).as_secs_f64();
            self.tokens = (self.tokens + dt * self.rate_per_s).min(self.burst);
        }
        self.last = Some(now);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            None
        } else {
            Some(Duration::from_secs_f64(
                (1.0 - self.tokens) / self.rate_per_s,
            ))
        }
    }

    /// Tokens in the bucket now [-] (after the last [`take`](Self::take)).
    pub fn tokens(&self) -> f64 {
        self.tokens
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// By hand: rate 10/s, burst 3. At t = 0 the bucket is full (3): three takes succeed
    /// (3 → 2 → 1 → 0). The fourth at t = 0 finds 0 tokens and must wait (1 − 0) / 10 = 100 ms.
    /// At t = 50 ms: 0 + 0.05 · 10 = 0.5 tokens, wait (1 − 0.5) / 10 = 50 ms. At t = 100 ms:
    /// 0.5 + 0.05 · 10 = 1.0: taken, 0 left. At t = 10 s the bucket refills to its burst, 3,
    /// not 100.
    #[test]
    fn line_budget_worked_example() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut b = LineBudget::new(10.0, 3.0);
        assert_eq!(b.take(ms(0)), None);
        assert_eq!(b.take(ms(0)), None);
        assert_eq!(b.take(ms(0)), None);
        let wait = b.take(ms(0)).expect("empty bucket");
        assert!((wait.as_secs_f64() - 0.100).abs() < 1e-9, "{wait:?}");
        let wait = b.take(ms(50)).expect("half a token");
        assert!((wait.as_secs_f64() - 0.050).abs() < 1e-9, "{wait:?}");
        assert_eq!(b.take(ms(100)), None);
        assert!(b.tokens().abs() < 1e-9);
        let _ = b.take(ms(10_000));
        assert!(
            (b.tokens() - 2.0).abs() < 1e-9,
            "refilled to burst 3, one taken"
        );
    }

    #[test]
    fn line_budget_refuses_nonsense_settings() {
        let mut b = LineBudget::new(f64::NAN, -4.0);
        let t0 = Instant::now();
        assert_eq!(b.take(t0), None);
        let wait = b.take(t0).expect("one token only");
        assert!((wait.as_secs_f64() - 1.0).abs() < 1e-9);
    }

    proptest! {
        /// Over any schedule of takes, no more tokens are handed out than the burst plus the
        /// rate times the elapsed time, and a refused take's wait is never longer than one
        /// token's refill time.
        #[test]
        fn line_budget_never_hands_out_more_than_its_rate(
            steps in proptest::collection::vec(0u64..5_000, 1..400),
            rate in 1.0f64..5_000.0,
            burst in 1.0f64..500.0,
        ) {
            let t0 = Instant::now();
            let mut b = LineBudget::new(rate, burst);
            let mut t_us = 0u64;
            let mut taken = 0u64;
            for dt in steps {
                t_us += dt;
                match b.take(t0 + Duration::from_micros(t_us)) {
                    None => taken += 1,
                    Some(w) => prop_assert!(w.as_secs_f64() <= 1.0 / rate + 1e-9),
                }
            }
            let bound = burst + rate * (t_us as f64) * 1e-6;
            prop_assert!(taken as f64 <= bound + 1e-6, "{taken} > {bound}");
        }
    }
}
