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
