//! The emulator's configuration is checked before anything is bound (issue 10: `--speedup
//! 4294967295` was accepted and hung the emulator, whose 2 ms tick then ran that many cycles).

use robot_io::RobotIoError;
use robot_io::emulator::{Emulator, EmulatorConfig, SimBackend};
use robot_io::sim::{SimConfig, SimRobot};

/// Starts (and stops) an emulator at `speedup`.
fn start(speedup: u32) -> robot_io::Result<()> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let sim = SimRobot::new(SimConfig::ur5e()).unwrap();
        let cfg = EmulatorConfig {
            speedup,
            ..EmulatorConfig::ephemeral()
        };
        let emu = Emulator::start(cfg, Box::new(SimBackend::new(sim))).await?;
        drop(emu); // shuts it down
        Ok(())
    })
}

#[test]
fn a_speedup_outside_1_to_100_is_refused_naming_the_key_and_the_bound() {
    assert!(start(1).is_ok());
    assert!(start(100).is_ok());
    for bad in [101, u32::MAX, 0] {
        match start(bad) {
            Err(RobotIoError::InvalidConfig { reason }) => {
                assert!(reason.contains("speedup"), "{reason}");
                if bad > 0 {
                    assert!(reason.contains("100"), "{reason}");
                }
            }
            Err(e) => panic!("speedup {bad}: {e}"),
            Ok(_) => panic!("speedup {bad} was accepted"),
        }
    }
}

/// `ClientWait::decide`, by hand with a 20 ms bound: a wake where the program awaits a command
/// begins a wait (t = 0), the next ones go on waiting (t = 5, 19.9 ms), the one at 20 ms times
/// out and runs the cycles, and later wakes of the same lateness run on without waiting; once
/// the client is current again (not awaited) the next lateness begins a new wait with a fresh
/// bound.
#[test]
fn client_wait_worked_example() {
    use robot_io::emulator::{ClientWait, WaitDecision};
    use std::time::Duration;
    let t0 = std::time::Instant::now();
    let at = |ms: f64| t0 + Duration::from_secs_f64(ms / 1e3);
    let mut w = ClientWait::new(Duration::from_millis(20));
    assert_eq!(w.decide(false, at(0.0)), WaitDecision::Run);
    assert_eq!(w.decide(true, at(0.0)), WaitDecision::Wait { began: true });
    assert_eq!(w.decide(true, at(5.0)), WaitDecision::Wait { began: false });
    assert_eq!(
        w.decide(true, at(19.9)),
        WaitDecision::Wait { began: false }
    );
    assert_eq!(w.decide(true, at(20.0)), WaitDecision::TimedOut);
    assert_eq!(w.decide(true, at(21.0)), WaitDecision::Run);
    assert_eq!(
        w.decide(true, at(500.0)),
        WaitDecision::Run,
        "runs on until current"
    );
    assert_eq!(w.decide(false, at(501.0)), WaitDecision::Run);
    assert_eq!(
        w.decide(true, at(502.0)),
        WaitDecision::Wait { began: true }
    );
    assert_eq!(
        w.decide(true, at(521.0)),
        WaitDecision::Wait { began: false }
    );
    assert_eq!(w.decide(true, at(522.0)), WaitDecision::TimedOut);
}
