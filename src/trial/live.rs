//! Live camera cues for a trial (`hrc-adapt trial --cues camera`, feature `vision`).
//!
//! **Threads.** Perception runs in its own thread at camera rate: frame → landmarks → cues
//! ([`assess::vision::Perception`]). It hands the latest [`CueFrame`] to the trial loop
//! through a single slot (a mutex around one value, overwritten by each new frame): the trial
//! loop never waits for perception, and a slow trial loop skips frames rather than queueing
//! them. The source and the models are opened inside the thread; [`LiveCues::start`] returns
//! once the first frame is there (or fails with the thread's error).
//!
//! **Time.** Camera timestamps are mapped onto the trial clock by an offset fixed when the
//! trial loop takes the first frame: that frame's trial time is the instant it was taken minus
//! the wall time since it was grabbed (the perception latency), so the supervisor's perception
//! age includes inference time. If a later frame would map into the future (the camera clock
//! running faster than the trial clock), the offset is moved back so that it maps to the
//! present. Between new frames the last one is held (sample-and-hold, as for recorded cues).
//!
//! **Privacy.** The thread writes `landmarks.csv` (camera time) into the trial folder; the
//! trial log keeps the cues. Camera images are stored only with `--store-video <path>`.
//!
//! A live operator is open loop for the trial's bookkeeping: the robot context (C, G) comes
//! from the task, as for recorded cues.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::Error;
use crate::error::ResultExt as _;
use assess::CueFrame;

use super::cues::CameraSpec;
use crate::vision_cmd::{
    LandmarkCsv, Perception, image_sink, intrinsics_override, load_extrinsics, open_source,
    pipeline_config,
};

/// The trial folder's landmark file.
pub(crate) const LANDMARKS_FILE: &str = "landmarks.csv";

/// How long [`LiveCues::start`] waits for the first frame (models load in about a second) [s].
const FIRST_FRAME_TIMEOUT: Duration = Duration::from_secs(30);

/// The newest frame the perception thread has produced.
#[derive(Debug)]
struct Latest {
    /// Frame counter (1 for the first frame).
    seq: u64,
    /// Camera time [s].
    camera_t: f64,
    /// When the frame left the source (before inference).
    grabbed: Instant,
    /// Its cues (workspace frame).
    frame: CueFrame,
}

/// The single slot shared with the perception thread.
#[derive(Debug, Default)]
struct Slot {
    latest: Option<Latest>,
    /// The thread has stopped (source ended, stop requested, or error).
    done: bool,
}

#[derive(Debug, Default)]
struct Shared {
    slot: Mutex<Slot>,
    changed: Condvar,
    stop: AtomicBool,
}

/// Live cues from a camera, perceived in a thread.
#[derive(Debug)]
pub(crate) struct LiveCues {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<crate::Result<()>>>,
    label: String,
    /// trial time = camera time + offset [s].
    offset: Option<f64>,
    /// Frames taken from the slot.
    seq: u64,
    held: Option<(CueFrame, f64)>,
}

impl LiveCues {
    /// Starts the perception thread on `spec`, writing `landmarks.csv` into `dir` (created),
    /// and waits for the first frame. Fails with the thread's error (no camera, no models, …).
    pub(crate) fn start(spec: &CameraSpec, dir: &Path) -> crate::Result<Self> {
        // A failed start leaves no run folder behind.
        let created = !dir.exists();
        std::fs::create_dir_all(dir).map_err(Error::io("create the run folder", dir))?;
        let result = Self::start_in(spec, dir);
        if result.is_err() && created {
            let _ = std::fs::remove_dir_all(dir);
        }
        result
    }

    fn start_in(spec: &CameraSpec, dir: &Path) -> crate::Result<Self> {
        let shared = Arc::new(Shared::default());
        let (described_tx, described_rx) = std::sync::mpsc::sync_channel::<String>(1);
        let thread = {
            let shared = shared.clone();
            let spec = spec.clone();
            let landmarks = dir.join(LANDMARKS_FILE);
            std::thread::Builder::new()
                .name("perception".into())
                .spawn(move || {
                    guarded(&shared, || {
                        perceive(&spec, &landmarks, &shared, &described_tx)
                    })
                })
                .map_err(|source| Error::Thread {
                    name: "perception thread",
                    source,
                })?
        };
        let mut live = Self {
            shared,
            thread: Some(thread),
            label: String::new(),
            offset: None,
            seq: 0,
            held: None,
        };
        // Wait for the first frame, or the thread's end.
        let deadline = Instant::now() + FIRST_FRAME_TIMEOUT;
        let ready = {
            let mut slot = live.shared.slot.lock().unwrap_or_else(|e| e.into_inner());
            while slot.latest.is_none() && !slot.done {
                let left = deadline.saturating_duration_since(Instant::now());
                if left.is_zero() {
                    break;
                }
                slot = live
                    .shared
                    .changed
                    .wait_timeout(slot, left)
                    .unwrap_or_else(|e| e.into_inner())
                    .0;
            }
            slot.latest.is_some()
        };
        if !ready {
            live.stop_thread()?;
            return Err(Error::Camera {
                camera: "the camera".into(),
                reason: format!("gave no frame within {} s", FIRST_FRAME_TIMEOUT.as_secs()),
            });
        }
        let described = described_rx.try_recv().unwrap_or_else(|_| "camera".into());
        live.label = format!("camera:{described}");
        Ok(live)
    }

    /// `camera:<source description>`: the run's `cue_source`.
    pub(crate) fn label(&self) -> &str {
        &self.label
    }

    /// Writes the cues held at trial time `tc` [s] into `out` (`out.t = tc`; `out.robot` is
    /// left to the caller) and returns their trial time [s]; `None` once the source has ended
    /// and its last frame was used.
    pub(crate) fn hold(&mut self, tc: f64, out: &mut CueFrame) -> Option<f64> {
        {
            let mut slot = self.shared.slot.lock().unwrap_or_else(|e| e.into_inner());
            match slot.latest.take() {
                Some(l) => {
                    self.seq = l.seq;
                    let age = l.grabbed.elapsed().as_secs_f64();
                    let offset = *self.offset.get_or_insert(tc - age - l.camera_t);
                    let mut t = l.camera_t + offset;
                    if t > tc {
                        // The camera clock runs ahead of the trial clock: re-anchor.
                        self.offset = Some(tc - l.camera_t);
                        t = tc;
                    }
                    self.held = Some((l.frame, t));
                }
                None if slot.done => return None,
                None => {}
            }
        }
        let (f, t) = self.held.as_ref()?;
        out.t = tc;
        out.head = f.head;
        out.body = f.body;
        out.hands = f.hands;
        Some(*t)
    }

    fn stop_thread(&mut self) -> crate::Result<()> {
        self.shared.stop.store(true, Ordering::Relaxed);
        match self.thread.take() {
            Some(handle) => match handle.join() {
                Ok(result) => result,
                Err(p) => Err(Error::panic("the perception thread", p.as_ref())),
            },
            None => Ok(()),
        }
    }

    /// Stops the perception thread and returns its outcome (an error if the camera or the
    /// inference failed); the landmark file and any stored video are closed.
    pub(crate) fn finish(mut self) -> crate::Result<()> {
        self.stop_thread()
    }
}

impl Drop for LiveCues {
    fn drop(&mut self) {
        let _ = self.stop_thread();
    }
}

/// Runs the perception thread's `body`: a panic in it becomes an error, and the slot is
/// marked done whatever happens, so the trial loop sees the cues end (`cues_ended`) and the
/// runtime's exit path stops the robot and finishes the logs (as `error`, with this error from
/// [`LiveCues::finish`]) instead of holding the last frame until the supervisor's perception
/// staleness stop.
fn guarded(shared: &Shared, body: impl FnOnce() -> crate::Result<()>) -> crate::Result<()> {
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(body))
        .unwrap_or_else(|p| Err(Error::panic("the perception thread", p.as_ref())));
    let mut slot = shared.slot.lock().unwrap_or_else(|e| e.into_inner());
    slot.done = true;
    shared.changed.notify_all();
    result
}

/// The perception thread: opens the source and the models, then frame → landmarks → cues
/// into the slot until the source ends or `stop`.
fn perceive(
    spec: &CameraSpec,
    landmarks_path: &Path,
    shared: &Shared,
    described: &std::sync::mpsc::SyncSender<String>,
) -> crate::Result<()> {
    let mut opened = open_source(&spec.input, &spec.camera, None)?;
    if spec.require_depth && !opened.source.has_depth() {
        return Err(Error::Camera {
            camera: opened.source.describe(),
            reason: "has no depth: with a real robot the operator's positions drive separation \
                     monitoring, and 2-D-only positions (estimated from assumed body sizes) are \
                     too rough for it; use a RealSense camera"
                .into(),
        });
    }
    let extrinsics = load_extrinsics(&spec.camera)?;
    let name = opened.source.describe();
    let _ = described.try_send(name.clone());
    let mut perception = Perception::load(
        pipeline_config(&spec.camera, false),
        extrinsics,
        intrinsics_override(&opened, spec.camera.intrinsics)?,
        spec.station.as_ref(),
    )?;
    let mut landmarks = LandmarkCsv::create(landmarks_path)?;
    let mut video = match &spec.store_video {
        Some(p) => Some(image_sink(p, "--store-video", opened.fps)?),
        None => None,
    };
    let mut seq = 0;
    while !shared.stop.load(Ordering::Relaxed) {
        let Some(frame) = opened
            .source
            .next_frame()
            .with_context(|| format!("reading {name}"))?
        else {
            break;
        };
        let grabbed = Instant::now();
        if let Some(v) = video.as_mut() {
            v.push(&frame.color)?;
        }
        let p = perception.step(&frame)?;
        landmarks.write(frame.index, frame.t, &p.landmarks)?;
        seq += 1;
        let mut slot = shared.slot.lock().unwrap_or_else(|e| e.into_inner());
        slot.latest = Some(Latest {
            seq,
            camera_t: frame.t,
            grabbed,
            frame: p.cues.frame,
        });
        shared.changed.notify_all();
    }
    landmarks.finish()?;
    if let Some(v) = video {
        v.finish()?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;
    use std::sync::atomic::AtomicBool;

    use super::*;

    /// A panic in the perception thread (a non-real-time thread) is an error, not an abort,
    /// and the slot is marked done so that the trial loop sees the cues end.
    #[test]
    fn a_panic_in_the_perception_thread_is_an_error_and_ends_the_cues() {
        let shared = Arc::new(Shared::default());
        let thread = {
            let shared = shared.clone();
            std::thread::spawn(move || guarded(&shared, || panic!("model file truncated")))
        };
        let result = thread.join().expect("the thread itself does not panic");
        let e = result.unwrap_err().with_causes().to_string();
        assert!(e.contains("panicked: model file truncated"), "{e}");
        assert!(
            shared.slot.lock().unwrap().done,
            "the loop would wait forever"
        );
        // And a normal end marks it done too.
        let ok = Shared::default();
        guarded(&ok, || Ok(())).unwrap();
        assert!(ok.slot.lock().unwrap().done);
    }
    use crate::trial::cues::CueSource;
    use crate::trial::operator::Level;
    use crate::trial::runtime::{RobotChoice, TrialSpec, run_trial_with_cues};
    use crate::vision_cmd::{CameraArgs, CueInput};

    /// A stand-in camera: an image folder of `n` copies of the bundled photo (an
    /// `ImageFolderSource`, through the same `open_source` as a real camera). There is no
    /// camera on the development machine.
    fn fake_camera(dir: &Path, n: usize) -> PathBuf {
        let images = dir.join("camera");
        std::fs::create_dir(&images).unwrap();
        let photo = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/images/pose_sitting.jpg");
        for i in 0..n {
            std::fs::copy(&photo, images.join(format!("{i:06}.jpg"))).unwrap();
        }
        images
    }

    fn spec(max_s: f64) -> TrialSpec {
        crate::trial::runtime::test_spec(Level::L1, 1, max_s)
    }

    fn camera(images: PathBuf, store_video: Option<PathBuf>) -> CueSource {
        CueSource::Camera(CameraSpec {
            input: CueInput::Images(images),
            camera: CameraArgs::default(),
            store_video,
            require_depth: false,
            station: None,
        })
    }

    /// A camera without depth is refused for a real robot before anything moves: its
    /// 2-D-only positions are too rough for separation monitoring. (The address is never
    /// contacted: perception starts, and fails, first.)
    #[test]
    fn a_camera_without_depth_is_refused_for_a_real_robot() {
        let dir = tempfile::tempdir().unwrap();
        let images = fake_camera(dir.path(), 1);
        let stop = AtomicBool::new(false);
        let e = run_trial_with_cues(
            &spec(5.0),
            &RobotChoice::ur("192.0.2.1"),
            &camera(images, None),
            &dir.path().join("run"),
            &stop,
            &mut |_| {},
        )
        .unwrap_err();
        let e = e.with_causes().to_string();
        assert!(e.contains("has no depth"), "{e}");
        assert!(!dir.path().join("run").exists());
    }

    /// The image and video files and folders in `dir` other than the trial's own plots
    /// (`indicator*.png`, `report_*.png`).
    fn image_files(dir: &Path) -> Vec<PathBuf> {
        let mut out = Vec::new();
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("");
            let plot =
                ext == "png" && (name.starts_with("indicator") || name.starts_with("report_"));
            if (["png", "jpg", "jpeg", "avi", "mp4"].contains(&ext) && !plot) || p.is_dir() {
                out.push(p);
            }
        }
        out
    }

    #[test]
    fn holding_maps_camera_time_onto_the_trial_clock_and_ends_with_the_source() {
        let shared = Arc::new(Shared::default());
        let mut live = LiveCues {
            shared: shared.clone(),
            thread: None,
            label: "camera:test".into(),
            offset: None,
            seq: 0,
            held: None,
        };
        let publish = |seq: u64, camera_t: f64, x: f64| {
            let mut frame = CueFrame::empty(camera_t);
            frame.head = Some(assess::HeadCue {
                position: assess::Vec3::new(x, 0.0, 1.0),
                facing: assess::Vec3::x(),
                confidence: 0.9,
            });
            shared.slot.lock().unwrap().latest = Some(Latest {
                seq,
                camera_t,
                grabbed: Instant::now(),
                frame,
            });
        };
        let mut out = CueFrame::empty(0.0);
        // The first frame (camera time 1000 s) taken at trial time 2 s is 2 s minus its age.
        publish(1, 1000.0, 1.0);
        let t = live.hold(2.0, &mut out).unwrap();
        assert!(t <= 2.0 && t > 1.9, "{t}");
        assert_eq!((out.t, out.head.unwrap().position.x), (2.0, 1.0));
        // No new frame: the last one is held with its own time.
        assert_eq!(live.hold(2.1, &mut out), Some(t));
        assert_eq!(out.t, 2.1);
        // The next frame 33 ms of camera time later maps 33 ms later.
        publish(2, 1000.033, 2.0);
        let t2 = live.hold(2.2, &mut out).unwrap();
        assert!((t2 - t - 0.033).abs() < 1e-9, "{t2} {t}");
        assert_eq!(out.head.unwrap().position.x, 2.0);
        // A camera clock running ahead is re-anchored to the present, never the future.
        publish(3, 1010.0, 3.0);
        assert_eq!(live.hold(2.3, &mut out), Some(2.3));
        // Source ended: the held frame was used, so the cues end.
        shared.slot.lock().unwrap().done = true;
        assert_eq!(live.hold(2.4, &mut out), None);
    }

    #[test]
    fn a_fake_camera_drives_a_sim_trial_and_leaves_cues_and_landmarks_only() {
        let dir = tempfile::tempdir().unwrap();
        let images = fake_camera(dir.path(), 3);
        let out_dir = dir.path().join("run");
        let stop = AtomicBool::new(false);
        let out = run_trial_with_cues(
            &spec(20.0),
            &RobotChoice::Sim,
            &camera(images.clone(), None),
            &out_dir,
            &stop,
            &mut |_| {},
        )
        .unwrap();
        crate::trial::runtime::assert_trial_files(&out);
        assert!(
            out.join(LANDMARKS_FILE).is_file(),
            "{LANDMARKS_FILE} missing"
        );
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
        let source = summary["meta"]["cue_source"].as_str().unwrap();
        assert!(source.starts_with("camera:image folder"), "{source}");
        assert_eq!(summary["meta"]["simulated"], false);
        // The mock clock outruns the camera; either the three frames end (cues_ended) or the
        // 20 s limit comes first.
        let reason = summary["finish_reason"].as_str().unwrap();
        assert!(["cues_ended", "max_duration"].contains(&reason), "{reason}");
        // Every frame perceived has its landmarks (33 pose points each, 3 frames at most).
        let text = std::fs::read_to_string(out.join(LANDMARKS_FILE)).unwrap();
        let pose_rows = text.lines().filter(|l| l.contains(",pose,")).count();
        assert!(
            pose_rows > 0 && pose_rows % 33 == 0 && pose_rows <= 99,
            "{pose_rows}"
        );
        // The assessment saw the camera's cues: the head cue is valid in indicators.csv.
        let table = std::fs::read_to_string(out.join("indicators.csv")).unwrap();
        let header: Vec<&str> = table.lines().next().unwrap().split(',').collect();
        let valid = header.iter().position(|h| *h == "valid").unwrap();
        assert!(
            table
                .lines()
                .skip(1)
                .all(|l| l.split(',').nth(valid) == Some("1")),
            "a frame without cues"
        );
        let report = std::fs::read_to_string(out.join("report.html")).unwrap();
        assert!(report.contains("LIVE CAMERA"), "report not labelled");
        // Privacy: no image or video anywhere in the run folder.
        assert_eq!(image_files(&out), Vec::<PathBuf>::new());
    }

    #[test]
    fn store_video_keeps_the_raw_frames_only_when_asked() {
        let dir = tempfile::tempdir().unwrap();
        let images = fake_camera(dir.path(), 3);
        let video = dir.path().join("raw");
        let stop = AtomicBool::new(false);
        let out = run_trial_with_cues(
            &spec(60.0),
            &RobotChoice::Sim,
            &camera(images, Some(video.clone())),
            &dir.path().join("run"),
            &stop,
            &mut |_| {},
        )
        .unwrap();
        let mut stored: Vec<String> = std::fs::read_dir(&video)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        stored.sort();
        // One PNG per frame perceived (the mock clock may end the trial before the third):
        // as many as frames in landmarks.csv, numbered from 0.
        let text = std::fs::read_to_string(out.join(LANDMARKS_FILE)).unwrap();
        let frames: std::collections::BTreeSet<&str> = text
            .lines()
            .skip(1)
            .filter_map(|l| l.split(',').next())
            .collect();
        assert!(!stored.is_empty());
        assert_eq!(stored.len(), frames.len());
        let want: Vec<String> = (0..stored.len()).map(|i| format!("{i:06}.png")).collect();
        assert_eq!(stored, want);
        // The run folder itself still holds no image.
        assert_eq!(image_files(&out), Vec::<PathBuf>::new());
    }

    #[test]
    fn no_camera_is_a_clear_error_not_the_simulated_operator() {
        let dir = tempfile::tempdir().unwrap();
        let stop = AtomicBool::new(false);
        let e = run_trial_with_cues(
            &spec(5.0),
            &RobotChoice::Sim,
            &CueSource::Camera(CameraSpec {
                input: CueInput::Webcam {
                    device: 57,
                    size: None,
                },
                camera: CameraArgs::default(),
                store_video: None,
                require_depth: false,
                station: None,
            }),
            &dir.path().join("run"),
            &stop,
            &mut |_| {},
        )
        .unwrap_err();
        let e = e.with_causes().to_string();
        assert!(
            e.contains("webcam 57: cannot open the camera (is /dev/video57 present"),
            "{e}"
        );
        // No trial was run, and no run folder is left.
        assert!(!dir.path().join("run").exists());
    }
}
