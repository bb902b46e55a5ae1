//! Statistics for policy A/B experiments and the paper's validation (issue 5; being written).
