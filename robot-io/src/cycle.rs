//! The time a control cycle stands for, one rule for every component that runs on the cycle.
//!
//! The trial runtime, the controller (`adapt::controller::Controller::step`) and the supervisor
//! each keep a clock of control cycles, taken from the robot's timestamps. When a sample comes late
//! (after the cycle that expected it ran on the held state) or the loop skips samples (missed
//! cycles), all three must agree on how far each cycle advanced: the controller advances its
//! plan by that time and the supervisor judges the implied speed and acceleration over it. A
//! disagreement of one cycle doubles the speed the supervisor sees after one missed cycle. So
//! all three take [`cycle_time_s`].

/// How far below one cycle after the previous a sample still counts as the next cycle's own
/// time, as a fraction of the cycle [1] (2 ns at 2 ms: far above rounding, far below timing).
pub const CYCLE_TIME_TOLERANCE: f64 = 1e-6;

/// The time [s] of the control cycle after one at `prev_s` [s], whose newest robot sample is at
/// `sample_s` [s]: the sample's time, but at least one cycle `cycle_s` [s] after `prev_s`.
///
/// - A sample more than a cycle after `prev_s` (missed cycles) moves the clock to it.
/// - A sample before `prev_s + cycle_s` (a held state, or a late sample that a cycle already
///   ran for) moves the clock by exactly one cycle.
/// - A sample at `prev_s + cycle_s` within [`CYCLE_TIME_TOLERANCE`] of a cycle (rounding)
///   gives the sample's time, so a clock that follows the robot's timestamps stays on them
///   instead of accumulating `prev + cycle` rounding. Either way the result is that cycle's
///   time to within the tolerance: the boundary has no knife-edge, where a rule comparing
///   with `prev_s` itself counts a late sample as a new cycle or not by floating-point noise.
/// - A non-finite `sample_s` counts as no sample: one cycle on.
///
/// ```
/// use robot_io::cycle_time_s;
/// let c = 0.002;
/// assert_eq!(cycle_time_s(1.000, 1.010, c), 1.010); // four missed cycles
/// assert_eq!(cycle_time_s(1.000, 1.000, c), 1.000 + c); // held state
/// assert_eq!(cycle_time_s(1.000, f64::NAN, c), 1.000 + c);
/// ```
#[must_use]
pub fn cycle_time_s(prev_s: f64, sample_s: f64, cycle_s: f64) -> f64 {
    let next = prev_s + cycle_s;
    if sample_s.is_finite() && sample_s >= next - CYCLE_TIME_TOLERANCE * cycle_s {
        sample_s
    } else {
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const C: f64 = 0.002;

    #[test]
    fn worked_example_a_late_sample_after_a_held_cycle() {
        // Computed by hand. Cycle at 95.420 (fresh); at 95.422 no sample came in time (held
        // state: the sample time is still 95.420); at 95.424 the late 95.422 sample arrives,
        // a hair above the predicted 95.422 by rounding; at 95.426 the loop gets the 95.428
        // sample (one skipped).
        let t1 = cycle_time_s(95.420, 95.420, C);
        assert!((t1 - 95.422).abs() < 1e-12);
        let t2 = cycle_time_s(t1, 95.422 + 1e-13, C);
        assert!(
            (t2 - 95.424).abs() < 1e-12,
            "the late sample is one cycle on: {t2}"
        );
        // A sample right at the next cycle, a hair early by rounding, is that cycle's own.
        assert_eq!(cycle_time_s(95.420, 95.422 - 1e-13, C), 95.422 - 1e-13);
        let t3 = cycle_time_s(t2, 95.428, C);
        assert_eq!(t3, 95.428);
        // Each cycle advanced by one cycle, then by two: 2 + 2 + 4 ms = the 8 ms the robot's
        // clock advanced from 95.420 to 95.428.
        assert!((t3 - 95.420 - 0.008).abs() < 1e-12);
    }

    proptest! {
        #[test]
        fn the_clock_advances_at_least_one_cycle_and_never_falls_behind_a_sample(
            prev in -1.0e4..1.0e4f64,
            offset in -0.1..0.1f64,
            cycle in 1.0e-4..0.01f64,
        ) {
            let sample = prev + offset;
            let t = cycle_time_s(prev, sample, cycle);
            prop_assert!(t >= prev + cycle * (1.0 - CYCLE_TIME_TOLERANCE));
            prop_assert!(t >= sample);
            // It is exactly one of the two candidates.
            prop_assert!(t == sample || t == prev + cycle);
        }

        #[test]
        fn a_sample_within_rounding_of_the_next_cycle_gives_that_cycle(
            prev in -1.0e4..1.0e4f64,
            noise in -1.0e-9..1.0e-9f64,
        ) {
            let sample = prev + C + noise;
            let t = cycle_time_s(prev, sample, C);
            prop_assert!((t - (prev + C)).abs() <= 1.0e-9 + 1.0e-12 * prev.abs());
            // On the robot's own timestamps, not on accumulated rounding.
            prop_assert_eq!(t, sample);
        }
    }
}
