//! Hesitation **episodes**: the assessor's hesitation against the simulated operator's, episode
//! by episode (issue 14, point 2), for `summary.json`'s `hesitation_episodes`.
//!
//! # Definitions
//! Times are trial time [s]; an assessed frame k stands for (t_k − Δt_k, t_k] as in the summary.
//! - **Ground-truth episode**: one `Hesitation { active: true }` … `{ active: false }` interval
//!   [s, e] of the simulated operator (closed at the trial's end if still open). Simulation, not
//!   measured data.
//! - **Assessed episode**: a maximal run of consecutive frames with `low_motion` (C ∧ G ∧
//!   v_h < v_th) that contains at least one frame with H = 1, i.e. a low-motion run that reached
//!   t_min (MODEL.md §7). Its `start_s` is the run's first frame's interval start (where §7
//!   attributes the hesitation, retroactively); `detected_s` is its first frame with H = 1 (when
//!   the assessment stream first says so, which is what the policy sees); `end_s` is its last
//!   frame's t.
//! - **Detected**: a ground-truth episode is detected when some frame with H = 1 has t in
//!   [s, e]; its **onset delay** is that first frame's t − s (the detection latency). The
//!   attributed onset (the run's `start_s` − s, negative when the hand was already still) is
//!   given as well.
//! - **Matched**: an assessed episode is matched when [start_s, end_s] overlaps a ground-truth
//!   episode. `phase` is the robot task phase at `detected_s` (from the `TaskPhase` events), so
//!   an unmatched episode says where it happened (e.g. `Present`: the operator's hand holding
//!   still at the part).
//! - recall = detected / ground-truth episodes, precision = matched / assessed episodes; `null`
//!   without a denominator.

use serde::{Deserialize, Serialize};

use super::{FrameRecord, r6};

/// One simulated hesitation episode and the assessor's detection of it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct TruthEpisode {
    /// Start [s].
    pub(crate) start_s: f64,
    /// End [s].
    pub(crate) end_s: f64,
    /// First frame with H = 1 in [start, end] [s], if any.
    pub(crate) detected_s: Option<f64>,
    /// detected − start [s] (the onset delay).
    pub(crate) delay_s: Option<f64>,
    /// The detecting assessed episode's attributed start − start [s] (negative when the hand
    /// was already still before the episode began).
    pub(crate) attributed_onset_s: Option<f64>,
}

/// One assessed hesitation episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct AssessedEpisode {
    /// The low-motion run's start [s] (its first frame's interval start).
    pub(crate) start_s: f64,
    /// The first frame with H = 1 [s].
    pub(crate) detected_s: f64,
    /// The run's last frame [s].
    pub(crate) end_s: f64,
    /// It overlaps a ground-truth episode.
    pub(crate) matched: bool,
    /// The robot task phase at `detected_s` (`null` before the first `TaskPhase` event).
    pub(crate) phase: Option<String>,
}

/// `summary.json`'s `hesitation_episodes`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct HesitationEpisodes {
    /// Ground-truth episodes [-].
    pub(crate) ground_truth: u64,
    /// Of them, detected [-].
    pub(crate) detected: u64,
    /// detected / ground_truth [-].
    pub(crate) recall: Option<f64>,
    /// Assessed episodes [-].
    pub(crate) assessed: u64,
    /// Of them, matched [-].
    pub(crate) matched: u64,
    /// matched / assessed [-].
    pub(crate) precision: Option<f64>,
    /// Median onset delay over the detected episodes [s] (the mean of the middle two for an
    /// even count).
    pub(crate) onset_delay_median_s: Option<f64>,
    /// Every ground-truth episode.
    pub(crate) truth_episodes: Vec<TruthEpisode>,
    /// Every assessed episode.
    pub(crate) assessed_episodes: Vec<AssessedEpisode>,
}

/// The median of `v` (mean of the middle two for an even count); `None` when empty.
pub(crate) fn median(v: &[f64]) -> Option<f64> {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return None;
    }
    s.sort_by(f64::total_cmp);
    let n = s.len();
    Some(if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    })
}

/// The episodes of one trial (see the module docs): `frames` in time order, `truth` the sorted,
/// disjoint ground-truth intervals [s], `phases` the task-phase changes (time, phase) in time
/// order.
pub(crate) fn compute(
    frames: &[&FrameRecord],
    truth: &[(f64, f64)],
    phases: &[(f64, &str)],
) -> HesitationEpisodes {
    // Assessed episodes: low-motion runs that reached t_min.
    let mut assessed: Vec<AssessedEpisode> = Vec::new();
    let mut run: Option<(f64, Option<f64>, f64)> = None; // (start, detected, end)
    let close = |run: &mut Option<(f64, Option<f64>, f64)>, out: &mut Vec<AssessedEpisode>| {
        if let Some((start_s, Some(detected_s), end_s)) = run.take() {
            out.push(AssessedEpisode {
                start_s,
                detected_s,
                end_s,
                matched: truth.iter().any(|&(s, e)| start_s <= e && end_s >= s),
                phase: phases
                    .iter()
                    .take_while(|p| p.0 <= detected_s)
                    .last()
                    .map(|p| p.1.to_string()),
            });
        }
    };
    for f in frames {
        // A frame with H = 1 is always part of a low-motion run (§7); take either as one.
        if f.low_motion || f.hesitating {
            let r = run.get_or_insert((f.t_s - f.dt_s, None, f.t_s));
            r.2 = f.t_s;
            if f.hesitating && r.1.is_none() {
                r.1 = Some(f.t_s);
            }
        } else {
            close(&mut run, &mut assessed);
        }
    }
    close(&mut run, &mut assessed);

    // Ground-truth episodes and their detection.
    let truth_episodes: Vec<TruthEpisode> = truth
        .iter()
        .map(|&(s, e)| {
            let first = frames
                .iter()
                .find(|f| f.hesitating && f.t_s >= s && f.t_s <= e)
                .map(|f| f.t_s);
            let attributed = first.and_then(|d| {
                assessed
                    .iter()
                    .find(|a| a.detected_s <= d && d <= a.end_s)
                    .map(|a| a.start_s - s)
            });
            TruthEpisode {
                start_s: r6(s),
                end_s: r6(e),
                detected_s: first.map(r6),
                delay_s: first.map(|d| r6(d - s)),
                attributed_onset_s: attributed.map(r6),
            }
        })
        .collect();
    let detected = truth_episodes
        .iter()
        .filter(|t| t.detected_s.is_some())
        .count() as u64;
    let matched = assessed.iter().filter(|a| a.matched).count() as u64;
    let delays: Vec<f64> = truth_episodes.iter().filter_map(|t| t.delay_s).collect();
    let ratio = |a: u64, b: usize| (b > 0).then(|| r6(a as f64 / b as f64));
    HesitationEpisodes {
        ground_truth: truth.len() as u64,
        detected,
        recall: ratio(detected, truth.len()),
        assessed: assessed.len() as u64,
        matched,
        precision: ratio(matched, assessed.len()),
        onset_delay_median_s: median(&delays).map(r6),
        truth_episodes,
        assessed_episodes: assessed
            .into_iter()
            .map(|a| AssessedEpisode {
                start_s: r6(a.start_s),
                detected_s: r6(a.detected_s),
                end_s: r6(a.end_s),
                ..a
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(t_s: f64, low_motion: bool, hesitating: bool) -> FrameRecord {
        FrameRecord {
            t_s,
            dt_s: 0.1,
            collaborating: true,
            low_motion,
            hesitating,
            hrc_cwl: 0.0,
            hrc_cwl_windowed: 0.0,
            dominant: None,
        }
    }

    /// A hand-made stream; every expected value is worked out by hand in the comments.
    #[test]
    fn episodes_of_a_hand_made_stream_are_counted_by_hand() {
        // Frames every 0.1 s from t = 0.1 to 3.0 (k = 1..30).
        // Low-motion runs (L) and H = 1 frames (H):
        //   run A: k = 3..8  (t 0.3–0.8), H from k = 6 (t 0.6)  → assessed, start 0.2, end 0.8
        //   run B: k = 12..13 (t 1.2–1.3), never H              → not an episode
        //   run C: k = 20..27 (t 2.0–2.7), H from k = 23 (t 2.3) → assessed, start 1.9, end 2.7
        let frames: Vec<FrameRecord> = (1..=30)
            .map(|k| {
                let t = k as f64 / 10.0;
                let low = (3..=8).contains(&k) || (12..=13).contains(&k) || (20..=27).contains(&k);
                let h = (6..=8).contains(&k) || (23..=27).contains(&k);
                f(t, low, h)
            })
            .collect();
        let refs: Vec<&FrameRecord> = frames.iter().collect();
        // Ground truth: [0.45, 1.0] (H frames in it: 0.6, 0.7, 0.8 → detected at 0.6, delay
        // 0.15, attributed onset 0.2 − 0.45 = −0.25), [1.1, 1.5] (no H frame in it → missed).
        let truth = [(0.45, 1.0), (1.1, 1.5)];
        // Phases: Approach from 0.0, Present from 2.2 (run C detected at 2.3 → Present).
        let phases = [(0.0, "Approach"), (2.2, "Present")];
        let e = compute(&refs, &truth, &phases);
        assert_eq!(e.ground_truth, 2);
        assert_eq!(e.detected, 1);
        assert_eq!(e.recall, Some(0.5));
        assert_eq!(e.assessed, 2);
        // A overlaps [0.45, 1.0]; C (1.9–2.7) overlaps nothing.
        assert_eq!(e.matched, 1);
        assert_eq!(e.precision, Some(0.5));
        assert_eq!(e.onset_delay_median_s, Some(0.15));
        assert_eq!(e.truth_episodes[0].detected_s, Some(0.6));
        assert_eq!(e.truth_episodes[0].attributed_onset_s, Some(-0.25));
        assert_eq!(e.truth_episodes[1].detected_s, None);
        assert_eq!(e.truth_episodes[1].delay_s, None);
        let a = &e.assessed_episodes;
        assert_eq!((a[0].start_s, a[0].detected_s, a[0].end_s), (0.2, 0.6, 0.8));
        assert_eq!(a[0].phase.as_deref(), Some("Approach"));
        assert!(a[0].matched);
        assert_eq!((a[1].start_s, a[1].detected_s, a[1].end_s), (1.9, 2.3, 2.7));
        assert_eq!(a[1].phase.as_deref(), Some("Present"));
        assert!(!a[1].matched);
    }

    #[test]
    fn without_episodes_the_ratios_are_null() {
        let frames = [f(0.1, false, false), f(0.2, true, false)];
        let refs: Vec<&FrameRecord> = frames.iter().collect();
        let e = compute(&refs, &[], &[]);
        assert_eq!((e.ground_truth, e.assessed), (0, 0));
        assert_eq!(
            (e.recall, e.precision, e.onset_delay_median_s),
            (None, None, None)
        );
    }

    #[test]
    fn an_episode_running_at_the_end_of_the_stream_counts() {
        // Run from t = 0.2 (start 0.1) with H at 0.5, to the last frame 0.6.
        let frames: Vec<FrameRecord> = (1..=6)
            .map(|k| f(k as f64 / 10.0, k >= 2, k >= 5))
            .collect();
        let refs: Vec<&FrameRecord> = frames.iter().collect();
        let e = compute(&refs, &[(0.3, 0.9)], &[]);
        assert_eq!(e.assessed, 1);
        assert_eq!(e.assessed_episodes[0].end_s, 0.6);
        assert_eq!(e.assessed_episodes[0].phase, None);
        assert_eq!(e.truth_episodes[0].delay_s, Some(0.2));
        assert_eq!(e.precision, Some(1.0));
    }

    #[test]
    fn the_median_of_an_even_count_is_the_mean_of_the_middle_two() {
        assert_eq!(median(&[3.0, 1.0, 2.0, 10.0]), Some(2.5));
        assert_eq!(median(&[4.0]), Some(4.0));
        assert_eq!(median(&[]), None);
    }
}
