//! Reading recorded cues: the documented cue CSV, and the KTH motion-capture handover layout.

pub mod cue_csv;
pub mod kth;
