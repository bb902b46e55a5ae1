//! # assess: vision-based cognitive-workload assessment for human–robot collaborative assembly
//!
//! This crate implements the attention–action model of Xiong et al.'s vision-based cognitive
//! workload paper (2026), as restated in [`spec`]: every formula, constant and decision where the
//! paper is silent (§ numbers in these docs refer to it). Per frame:
//!
//! 1. each cue (head, upper body, hand) gives evidence S_i^c for every calibrated [`Area`];
//! 2. reliability-weighted fusion gives S_i and the raw state F_raw (τ);
//! 3. temporal confirmation over the last M valid frames gives the confirmed state F;
//! 4. area demand D_i = T_i / T_v gives AED, TID, ICD (and COL);
//! 5. perceptual and action sub-states give ABI (diagnostic);
//! 6. confirmed switches weighted by context give ASD_ctx;
//! 7. gated low-motion hand runs give OHD;
//! 8. the composite HRC-CWL, its category and the dominant indicator.
//!
//! The main types are [`Workspace`] (the calibrated areas), [`AssessConfig`] (every constant,
//! defaulting to the [`spec`]'s values), [`CueFrame`] (one frame of input), [`Assessor`] and
//! [`Assessment`]. [`Assessor::update`] is O(1) per frame and allocates nothing after
//! construction.
//!
//! ```
//! use assess::{Assessor, AssessConfig, CueFrame, HeadCue, Vec3, Workspace};
//!
//! let workspace = Workspace::from_toml_str(r#"
//!     [[area]]
//!     name = "assembly"
//!     role = "assembly"
//!     min_m = [0.3, -0.2, 0.7]
//!     max_m = [0.7, 0.2, 0.9]
//!     [[area]]
//!     name = "instruction"
//!     role = "instruction"
//!     min_m = [0.3, 0.6, 1.0]
//!     max_m = [0.5, 0.9, 1.4]
//! "#)?;
//! let mut assessor = Assessor::new(workspace, AssessConfig::default())?;
//! // An operator at the origin, 1.2 m up, looking at the assembly area centre for 2 s at 30 fps.
//! for k in 0..60 {
//!     let mut frame = CueFrame::empty(k as f64 / 30.0);
//!     frame.head = Some(HeadCue {
//!         position: Vec3::new(0.0, 0.0, 1.2),
//!         facing: Vec3::new(0.5, 0.0, -0.4),
//!         confidence: 0.9,
//!     });
//!     assessor.update(&frame);
//! }
//! let a = assessor.assessment();
//! assert_eq!(a.confirmed, assessor.workspace().by_role(assess::AreaRole::Assembly));
//! assert!(a.cumulative.aed > 0.8);
//! # Ok::<(), assess::AssessError>(())
//! ```

mod area;
mod assessment;
mod assessor;
mod config;
mod confirm;
mod cue;
mod dominant;
mod error;
pub mod evidence;
pub mod filter;
mod hesitation;
pub mod io;
#[doc = include_str!("spec.md")]
pub mod spec {}
#[cfg(feature = "vision")]
pub mod vision;
mod window;

pub use area::{Area, AreaBox, AreaId, AreaRole, Station, Workspace};
pub use assessment::{Assessment, Category, Dominant, Indicator, Indicators};
pub use assessor::Assessor;
pub use config::{
    AssessConfig, BaselineMode, COMPONENT_KEYS, ComponentValues, CompositeConfig,
    ConfirmationConfig, CueWeights, DemandConfig, DominantConfig, FusionConfig, HesitationConfig,
    MAX_FRAMES, OneEuroConfig, SwitchingConfig, WindowConfig,
};
pub use cue::{BodyCue, CueFrame, Hand, HandCue, HeadCue, RobotContext};
pub use error::{AssessError, Result};

/// A 3-vector in the workspace frame (z up) [m] or a direction [-].
pub type Vec3 = nalgebra::Vector3<f64>;
