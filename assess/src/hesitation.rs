//! §7 the adaptive low-motion threshold v_th: a running median of recent hand speeds.

/// The v_h samples of earlier collaboration frames from the last `horizon_s` seconds, kept both
/// in time order (for expiry) and sorted (for the median).
///
/// Insertion and removal shift the sorted array: O(K) memory moves for K samples in the horizon
/// (≈ 300 at 30 fps), with no allocation after construction.
#[derive(Debug, Clone)]
pub(crate) struct SpeedSamples {
    /// Time-ordered ring of (t [ns], v [m/s], Δt [ns]).
    ring: Vec<(i64, f64, i64)>,
    oldest: usize,
    len: usize,
    sorted: Vec<f64>,
    sum_dt_ns: i64,
    /// The median horizon [ns].
    horizon_ns: i64,
}

impl SpeedSamples {
    pub(crate) fn new(horizon_s: f64, max_rate_hz: f64) -> Self {
        let cap = (horizon_s * max_rate_hz).ceil() as usize + 2;
        Self {
            ring: vec![(0, 0.0, 0); cap],
            oldest: 0,
            len: 0,
            sorted: Vec::with_capacity(cap),
            sum_dt_ns: 0,
            horizon_ns: crate::window::seconds_to_ns(horizon_s),
        }
    }

    fn remove_oldest(&mut self) {
        let (_, v, dt) = self.ring[self.oldest];
        let pos = self.sorted.partition_point(|&x| x < v);
        // `v` is a copy of a stored value, so it is found exactly at `pos`.
        if pos < self.sorted.len() {
            self.sorted.remove(pos);
        }
        self.sum_dt_ns -= dt;
        self.oldest = (self.oldest + 1) % self.ring.len();
        self.len -= 1;
    }

    /// Drop the samples with t_now − t_k ≥ horizon, in whole nanoseconds.
    pub(crate) fn expire(&mut self, t_now_ns: i64) {
        while self.len > 0 && t_now_ns - self.ring[self.oldest].0 >= self.horizon_ns {
            self.remove_oldest();
        }
    }

    /// Add a sample (finite `v` [m/s]) taken at `t_ns` [ns] on a frame that contributed
    /// `dt_ns` [ns].
    pub(crate) fn push(&mut self, t_ns: i64, v: f64, dt_ns: i64) {
        if self.len == self.ring.len() {
            self.remove_oldest();
        }
        let i = (self.oldest + self.len) % self.ring.len();
        self.ring[i] = (t_ns, v, dt_ns);
        self.len += 1;
        let pos = self.sorted.partition_point(|&x| x < v);
        self.sorted.insert(pos, v);
        self.sum_dt_ns += dt_ns;
    }

    /// Σ Δt_k of the samples [ns].
    pub(crate) fn sum_dt_ns(&self) -> i64 {
        self.sum_dt_ns
    }

    /// The median; the mean of the two middle values for an even count; `None` when empty.
    pub(crate) fn median(&self) -> Option<f64> {
        let n = self.sorted.len();
        if n == 0 {
            None
        } else if n % 2 == 1 {
            Some(self.sorted[n / 2])
        } else {
            Some(0.5 * (self.sorted[n / 2 - 1] + self.sorted[n / 2]))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: i64 = 1_000_000_000;

    #[test]
    fn median_and_expiry() {
        let mut s = SpeedSamples::new(10.0, 30.0);
        assert_eq!(s.median(), None);
        s.push(0, 0.3, 1);
        s.push(S, 0.1, 1);
        s.push(2 * S, 0.2, 1);
        assert_eq!(s.median(), Some(0.2));
        s.push(3 * S, 0.4, 1);
        // Even count: (0.2 + 0.3) / 2.
        assert!((s.median().unwrap() - 0.25).abs() < 1e-15);
        // At t = 11 the sample from t = 0 and 1 expire (11 − 1 = 10 ≥ 10): left 0.2, 0.4.
        s.expire(11 * S);
        assert!((s.median().unwrap() - 0.3).abs() < 1e-15);
        assert_eq!(s.sum_dt_ns(), 2);
    }

    /// Worked example (by hand), MODEL.md "every time comparison is exact": on a 25 fps stream
    /// (t_k = k · 0.04 s) a sample from frame 160 (6.4 s) is exactly 10 s old on frame 410
    /// (16.4 s) and leaves the median there; in floating point 410 · 0.04 − 160 · 0.04 =
    /// 9.999999999999998 < 10, and a077dd5 kept it.
    #[test]
    fn a_sample_exactly_ten_seconds_old_has_left_the_median() {
        let t = |k: u32| crate::window::seconds_to_ns(f64::from(k) * 0.04);
        assert!(
            crate::window::tests::float_age(410, 160) < 10.0,
            "the float difference is below 10 s"
        );
        let mut s = SpeedSamples::new(10.0, 30.0);
        s.push(t(160), 0.9, 40_000_000);
        s.push(t(300), 0.1, 40_000_000);
        s.expire(t(409));
        assert_eq!(
            s.median(),
            Some(0.5),
            "9.96 s old: still in (mean of 0.9 and 0.1)"
        );
        s.expire(t(410));
        assert_eq!(s.median(), Some(0.1), "exactly 10 s old: out");
        assert_eq!(s.sum_dt_ns(), 40_000_000);
    }
}
