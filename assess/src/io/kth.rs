//! The KTH handover dataset layout (OptiTrack rigid bodies at 120 Hz) → CueFrames for the taker.
