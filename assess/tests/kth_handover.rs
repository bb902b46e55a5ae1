//! Real data: the bundled KTH human–human handover (`data/human-motion/kth-handover/`, OptiTrack at
//! 120 Hz, 801 rows, MIT licence), read for the taker by `assess::io::kth` and assessed with the
//! default configuration in the calibration `config/kth-handover-workspace.toml`.
//!
//! Nothing here is simulated. The figures the comments quote come from
//! `python3 scripts/analysis/kth_frames.py`, which reads the same files independently of the
//! Rust reader (the section numbers below are its sections).

use assess::io::kth::{KthOptions, KthRecording, read_recording};
use assess::{AreaId, AreaRole, AssessConfig, Assessment, Assessor, CueFrame, Hand, Workspace};
use hrc_adapt_tests::{config_dir, data_dir};

/// Rows in the recording.
const ROWS: usize = 801;
/// The recording rate [Hz].
const RATE_HZ: f64 = 120.0;

fn recording(opts: &KthOptions) -> KthRecording {
    read_recording(&data_dir().join("human-motion").join("kth-handover"), opts)
        .expect("read the KTH recording")
}

fn workspace() -> Workspace {
    Workspace::from_toml_file(config_dir().join("kth-handover-workspace.toml"))
        .expect("load the calibration")
}

/// Every frame's assessment, in order.
fn assess(frames: &[CueFrame]) -> Vec<Assessment> {
    let mut assessor =
        Assessor::new(workspace(), AssessConfig::default()).expect("default config is valid");
    frames.iter().map(|f| assessor.update(f).clone()).collect()
}

fn role(role: AreaRole) -> Option<AreaId> {
    Some(
        workspace()
            .by_role(role)
            .expect("the calibration has all four roles"),
    )
}

#[test]
fn reader_finds_the_transfer_where_the_analysis_does() {
    let rec = recording(&KthOptions::default());
    // One frame per row; the recording has no missing or non-finite value (script section 1), so
    // every frame has all four cues.
    assert_eq!(rec.frames.len(), ROWS);
    assert!(
        rec.frames
            .iter()
            .all(|f| f.head.is_some() && f.body.is_some() && f.hands.iter().all(Option::is_some))
    );
    // Script sections 5–6: the baton's 0.1 s speed first exceeds 0.2 m/s at row 254; the taker's
    // |F| first exceeds 5 N at row 396; the giver's |F| falls below 1 N at row 427; the taker's
    // right hand holds the baton at the end (0.211 m, the holding distance; the left 0.689 m).
    let e = rec.events;
    let row = |t: Option<f64>| t.map(|t| (t * RATE_HZ).round() as usize);
    assert_eq!(row(e.reach_onset_s), Some(254));
    assert_eq!(row(e.grasp_s), Some(396));
    assert_eq!(row(e.release_s), Some(427));
    assert_eq!(e.receiving_hand, Some(Hand::Right));
}

#[test]
fn the_taker_attends_to_the_handover_throughout_the_transfer() {
    let rec = recording(&KthOptions::default());
    let out = assess(&rec.frames);
    let col = role(AreaRole::Collaboration);
    let onset = rec.events.reach_onset_s.expect("reach onset");
    let release = rec.events.release_s.expect("release");

    // Before the giver reaches, the head's −y axis is 16.9–23.7° from r_col and at least 59.7°
    // from every other r_i (script section 7), so the raw state is the handover area from the
    // first frame, and it is confirmed on the 8th valid frame (index 7): a strict majority of
    // M = 15 needs 8 votes. Nothing is confirmed before.
    assert!(out[..7].iter().all(|a| a.confirmed.is_none()));
    assert_eq!(out[7].confirmed, col);

    // From the reach onset to the release the head stays 16.7–25.7° from r_col and ≥ 59.3° from
    // every other centre, and the chest faces the giver (5.6° median, horizontally, section 4),
    // so the confirmed state — and the perceptual (head + chest) sub-state — is the handover
    // area on every frame of the approach and of the transfer (grasp 3.300 s → release 3.558 s).
    for a in out.iter().filter(|a| a.t >= onset && a.t < release) {
        assert_eq!(a.confirmed, col, "t = {:.3} s", a.t);
        assert_eq!(a.perceptual.0, col, "t = {:.3} s", a.t);
    }
    // During the transfer the taker's hand is inside the handover box too (it is inside from
    // 2.525 s to 3.875 s; the calibration's comments): action and perception agree.
    for a in out
        .iter()
        .filter(|a| a.t >= rec.events.grasp_s.unwrap() && a.t < release)
    {
        assert_eq!(a.action.0, col, "t = {:.3} s", a.t);
    }

    // Hence COL is at least the share of the valid time from the first confirmation to the
    // release, (3.558 − 7/120) / 6.667 = 0.525, which is more than the rest of the recording
    // could give AED, TID and ICD together (≤ 1 − 0.525).
    let last = out.last().unwrap().cumulative;
    let floor = (release - 7.0 / RATE_HZ) / last.valid_time_s;
    assert!(last.col >= floor - 1e-9, "COL {} < {floor}", last.col);
    assert!(last.col > last.aed + last.tid + last.icd, "{last:?}");
}

#[test]
fn validity_and_demand_shares() {
    let rec = recording(&KthOptions::default());
    let out = assess(&rec.frames);
    // Every frame has all cues, so every frame is valid.
    assert!(out.iter().all(|a| a.valid && !a.last_rejected));
    // T_v is the recording length, 800 intervals of 1/120 s = 6.6667 s. The assessor integrates
    // Δt in whole nanoseconds, so each interval may be off by up to 0.5 ns.
    let last = out.last().unwrap();
    let length = (ROWS - 1) as f64 / RATE_HZ;
    let quantum = (ROWS - 1) as f64 * 0.5e-9;
    assert!(
        (last.cumulative.valid_time_s - length).abs() <= quantum,
        "T_v = {} s, recording {length} s",
        last.cumulative.valid_time_s
    );
    // The D_i share T_v between the areas (with ∅ taking the rest), so they sum to at most 1.
    let sum: f64 = last.area_demand.iter().sum();
    assert!(sum <= 1.0 + 1e-12, "Σ D_i = {sum}");
}

#[test]
fn waiting_at_the_handover_is_hesitation_only_under_collaboration() {
    let rec = recording(&KthOptions::default());
    let out = assess(&rec.frames);
    let e = rec.events;
    let (onset, grasp, release) = (
        e.reach_onset_s.unwrap(),
        e.grasp_s.unwrap(),
        e.release_s.unwrap(),
    );
    let last = out.last().unwrap().cumulative;

    // C holds from row 254 to row 426 (release at row 427 is excluded): 173 frames, each adding
    // one interval, so T_collab = release − onset up to the nanosecond quantisation.
    assert!(
        (last.collaboration_time_s - (release - onset)).abs() <= 173.0 * 0.5e-9,
        "T_collab = {} s",
        last.collaboration_time_s
    );

    // The taker's right hand arrives at the baton and slows down. Its One-Euro-filtered speed
    // (script section 6 replicates the filter with the same constants) is below 0.10 m/s on row
    // 362 alone (0.093; row 363 is 0.102), then on rows 364–421 (3.033–3.508 s; 0.091 on row 364,
    // 0.101 on row 422), while the grip force builds up (taker |F| > 5 N at 3.300 s) and the
    // giver lets go (3.558 s). v_th is v_max = 0.10 m/s there: during C the hand moves at
    // 0.2–0.66 m/s, so 0.35 × median is above v_max. The one-row run is shorter than
    // t_min = 0.3 s and does not count; the 58-row run does, whole: T_hes = 58/120 s.
    assert!(last.ohd > 0.0);
    assert!(
        (last.hesitation_time_s - 58.0 / RATE_HZ).abs() <= 58.0 * 0.5e-9,
        "T_hes = {} s",
        last.hesitation_time_s
    );
    // The counted run is the waiting at the baton: it starts after the reach onset and before
    // the grasp, and on each of its frames the right (receiving) hand is the active hand and is
    // inside the handover box (it is there from 2.525 s to 3.875 s).
    let first_hes = out
        .iter()
        .position(|a| a.hesitating)
        .expect("a hesitation frame");
    let start = (0..=first_hes)
        .rev()
        .take_while(|&k| out[k].low_motion)
        .last()
        .unwrap();
    let end = (first_hes..out.len())
        .take_while(|&k| out[k].low_motion)
        .last()
        .unwrap();
    assert!(
        out[start].t > onset && out[start].t < grasp,
        "run starts at {} s",
        out[start].t
    );
    assert!(out[end].t < release, "run ends at {} s", out[end].t);
    let ws = workspace();
    let col_box = &ws.area(role(AreaRole::Collaboration).unwrap()).shape;
    for (a, f) in out[start..=end].iter().zip(&rec.frames[start..=end]) {
        assert_eq!(a.active_hand, Some(Hand::Right), "t = {:.3} s", a.t);
        let hand = f.hand(Hand::Right).unwrap().position;
        assert!(col_box.contains(&hand), "t = {:.3} s: hand {hand:?}", a.t);
    }
    // Nothing outside C ∧ G is low motion, though the filtered right-hand speed is below
    // 0.10 m/s for longer before the reach (rows 1–239) and after the set-down (rows 647–800).
    assert!(
        out.iter()
            .zip(&rec.frames)
            .all(|(a, f)| !a.low_motion || (f.robot.collaborating && f.robot.incomplete))
    );

    // Control: the same frames with C never set. H needs C, so OHD and T_collab are 0 and no
    // frame is low motion; C does not enter the area states, so those are unchanged.
    let never = KthOptions {
        collaboration_s: Some((0.0, 0.0)),
        ..KthOptions::default()
    };
    let control = assess(&recording(&never).frames);
    let c_last = control.last().unwrap().cumulative;
    assert_eq!(c_last.ohd, 0.0);
    assert_eq!(c_last.collaboration_time_s, 0.0);
    assert!(control.iter().all(|a| !a.low_motion && !a.hesitating));
    assert!(
        control
            .iter()
            .zip(&out)
            .all(|(c, a)| c.confirmed == a.confirmed)
    );
}
