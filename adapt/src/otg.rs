//! (issue 4: kinematics and trajectory generation; being written)
