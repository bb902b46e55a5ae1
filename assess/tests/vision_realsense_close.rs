//! Closing a `.bag` source lets go of everything librealsense2 started for it: its playback
//! threads end, also when it is closed mid-file while the playback waits for the reader.
//!
//! In a file of its own, so that the only threads of this process are the test harness's and
//! librealsense2's (threads are counted from `/proc/self/task`).
//!
//! Regression: the first sensor-callback player leaked one sensor handle per open (for its
//! `DEPTH_UNITS` option), which kept the playback device and its threads alive; a process then
//! crashed at exit while those threads still logged (`SIGSEGV` in the binary's bag tests).
#![cfg(all(feature = "realsense", target_os = "linux"))]

use std::path::PathBuf;
use std::time::{Duration, Instant};

use assess::vision::FrameSource;
use assess::vision::source::realsense::RealSenseSource;

fn bag() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/bag/synthetic_plane.bag")
}

fn threads() -> usize {
    std::fs::read_dir("/proc/self/task")
        .expect("/proc/self/task")
        .count()
}

/// Waits (up to 5 s) for the thread count to fall to `target`; the last count seen.
fn settle_to(target: usize) -> usize {
    let started = Instant::now();
    loop {
        let now = threads();
        if now <= target || started.elapsed() > Duration::from_secs(5) {
            return now;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn closing_a_bag_source_ends_its_threads_at_any_point_of_the_file() {
    let before = threads();
    // 0: closed at once (the playback is still reading the file's header); 1, 2: mid-file,
    // with the playback blocked handing over a frame; 5: at the end.
    for read in [0usize, 1, 2, 5] {
        let mut source = RealSenseSource::open_bag(bag()).expect("open the bag");
        assert!(threads() > before, "playback runs on threads of its own");
        for k in 0..read {
            assert!(
                source.next_frame().expect("a frame").is_some(),
                "frame {k} of {read}"
            );
        }
        drop(source);
        let after = settle_to(before);
        assert_eq!(
            after, before,
            "closed after {read} frames: {after} threads left, {before} before it opened"
        );
    }
    // The file opens again and plays from its start.
    let mut source = RealSenseSource::open_bag(bag()).expect("open again");
    let first = source.next_frame().expect("a frame").expect("not the end");
    assert_eq!(first.index, 0);
}
