//! (issue 3: RTDE side; being written)
