//! §8 windowed sums: a ring of per-frame contributions over the horizon H, with running totals.
//!
//! Times are integer nanoseconds, so adding a frame and later removing it leaves the totals
//! exactly as they were (no floating-point drift over long trials).

/// One frame's contributions to the integrals.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct FrameContribution {
    /// Frame time, rounded to whole nanoseconds [ns].
    pub(crate) t_ns: i64,
    /// Δt_k [ns].
    pub(crate) dt_ns: i64,
    /// v_F.
    pub(crate) valid: bool,
    /// Confirmed state code (area index, or N for ∅).
    pub(crate) state: u16,
    /// v_AB.
    pub(crate) ab_valid: bool,
    /// I_AB.
    pub(crate) ab_inconsistent: bool,
    /// C(t).
    pub(crate) collaborating: bool,
    /// H(t) (possibly set later, retroactively).
    pub(crate) hesitating: bool,
    /// Cost of the switch event on this frame (0 if none).
    pub(crate) switch_cost: f64,
}

/// Integrals over a set of frames [ns], shared by the cumulative and the windowed indicators.
#[derive(Debug, Clone, Default)]
pub(crate) struct Totals {
    /// T_i per area [ns].
    pub(crate) area_ns: Vec<i64>,
    /// T_v [ns].
    pub(crate) valid_ns: i64,
    /// ∫ v_AB [ns].
    pub(crate) ab_valid_ns: i64,
    /// ∫ I_AB [ns].
    pub(crate) ab_inconsistent_ns: i64,
    /// T_collab [ns].
    pub(crate) collab_ns: i64,
    /// T_hes [ns].
    pub(crate) hes_ns: i64,
    /// Σ switch costs.
    pub(crate) switch_cost: f64,
}

impl Totals {
    pub(crate) fn new(n_areas: usize) -> Self {
        Self {
            area_ns: vec![0; n_areas],
            ..Self::default()
        }
    }

    /// Add (`sign` = 1) or remove (`sign` = −1) one frame's contributions.
    pub(crate) fn apply(&mut self, f: &FrameContribution, sign: i64) {
        let dt = sign * f.dt_ns;
        if f.valid {
            self.valid_ns += dt;
            if let Some(a) = self.area_ns.get_mut(f.state as usize) {
                *a += dt;
            }
        }
        if f.ab_valid {
            self.ab_valid_ns += dt;
            if f.ab_inconsistent {
                self.ab_inconsistent_ns += dt;
            }
        }
        if f.collaborating {
            self.collab_ns += dt;
        }
        if f.hesitating {
            self.hes_ns += dt;
        }
        self.switch_cost += sign as f64 * f.switch_cost;
    }
}

/// `s` [s] rounded to whole nanoseconds [ns] (durations from the config, absolute frame times).
pub(crate) fn seconds_to_ns(s: f64) -> i64 {
    (s * 1e9).round() as i64
}

/// The frames with t_now − t_k < H, and their totals.
#[derive(Debug, Clone)]
pub(crate) struct Window {
    ring: Vec<FrameContribution>,
    /// Sequence number of the oldest frame in the ring.
    oldest_seq: u64,
    len: usize,
    /// H [ns].
    horizon_ns: i64,
    pub(crate) totals: Totals,
    /// Number of switch events in the window (to reset the cost sum to exactly 0 when none).
    switches: u64,
    pub(crate) overflowed: bool,
}

impl Window {
    pub(crate) fn new(n_areas: usize, horizon_s: f64, max_rate_hz: f64) -> Self {
        let cap = (horizon_s * max_rate_hz).ceil() as usize + 2;
        Self {
            ring: vec![FrameContribution::default(); cap],
            oldest_seq: 0,
            len: 0,
            horizon_ns: seconds_to_ns(horizon_s),
            totals: Totals::new(n_areas),
            switches: 0,
            overflowed: false,
        }
    }

    fn slot(&self, seq: u64) -> usize {
        (seq % self.ring.len() as u64) as usize
    }

    fn evict_oldest(&mut self) {
        let i = self.slot(self.oldest_seq);
        let old = self.ring[i];
        self.totals.apply(&old, -1);
        if old.switch_cost != 0.0 {
            self.switches -= 1;
            if self.switches == 0 {
                self.totals.switch_cost = 0.0;
            }
        }
        self.oldest_seq += 1;
        self.len -= 1;
    }

    /// Drop the frames that left the window at time `t_now`, then add frame number `seq`.
    pub(crate) fn push(&mut self, seq: u64, f: FrameContribution) {
        // Exact: t_now − t_k ≥ H in whole nanoseconds (MODEL.md: every time comparison).
        while self.len > 0 && f.t_ns - self.ring[self.slot(self.oldest_seq)].t_ns >= self.horizon_ns
        {
            self.evict_oldest();
        }
        if self.len == self.ring.len() {
            self.evict_oldest();
            self.overflowed = true;
        }
        if self.len == 0 {
            self.oldest_seq = seq;
        }
        let i = self.slot(seq);
        self.ring[i] = f;
        self.len += 1;
        self.totals.apply(&f, 1);
        if f.switch_cost != 0.0 {
            self.switches += 1;
        }
    }

    /// Mark frames `from_seq..=to_seq` (those still in the window) as hesitation.
    pub(crate) fn mark_hesitation(&mut self, from_seq: u64, to_seq: u64) {
        for seq in from_seq.max(self.oldest_seq)..=to_seq {
            let i = self.slot(seq);
            let f = &mut self.ring[i];
            if !f.hesitating {
                f.hesitating = true;
                self.totals.hes_ns += f.dt_ns;
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The age of frame `k` on frame `k_now` of a 25 fps stream as a float difference of
    /// absolute times, k_now · 0.04 − k · 0.04 [s]: what a077dd5 compared.
    pub(crate) fn float_age(k_now: u32, k: u32) -> f64 {
        f64::from(k_now) * 0.04 - f64::from(k) * 0.04
    }

    /// Frame k of a 25 fps stream, with its time as a camera clock gives it: k · 0.04 [s].
    fn frame_25fps(k: u32, switch_cost: f64) -> FrameContribution {
        FrameContribution {
            t_ns: seconds_to_ns(f64::from(k) * 0.04),
            dt_ns: 40_000_000,
            valid: true,
            switch_cost,
            ..FrameContribution::default()
        }
    }

    /// Worked example (by hand), MODEL.md "every time comparison is exact": on a 25 fps stream
    /// a switch on frame 53 (t = 2.12 s) is exactly H = 30 s old on frame 803 (t = 32.12 s),
    /// so it has left the window there: windowed switch cost 0, where frame 802 still holds
    /// it. In floating point 803 · 0.04 − 53 · 0.04 = 29.999999999999996 < 30, and the
    /// comparison on a077dd5 kept the switch (win_asd_ctx 0.033 instead of 0).
    #[test]
    fn a_switch_exactly_h_old_has_left_the_window() {
        assert!(float_age(803, 53) < 30.0, "the float difference is below H");
        let mut w = Window::new(4, 30.0, 30.0);
        for k in 0..=802 {
            w.push(
                u64::from(k),
                frame_25fps(k, if k == 53 { 1.0 } else { 0.0 }),
            );
        }
        assert_eq!(w.totals.switch_cost, 1.0, "29.96 s old: still in");
        w.push(803, frame_25fps(803, 0.0));
        assert_eq!(w.totals.switch_cost, 0.0, "exactly 30 s old: out");
        // The window then holds frames 54..=803: 750 frames of 40 ms, exactly 30 s.
        assert_eq!(w.totals.valid_ns, 30_000_000_000);
    }
}
