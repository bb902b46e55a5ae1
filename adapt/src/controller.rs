//! (issue 4: handover task and the 500 Hz controller; being written)
