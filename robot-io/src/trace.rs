//! (issue 3: simulation and traces; being written)
