"""ur_rtde's RTDEControlInterface against `hrc-adapt emulate --sim` (issue 11, point 2).

ur_rtde uploads its own control script (rtde_control.script) and drives it over RTDE
registers; the emulator recognises the script and runs its protocol on the simulated arm
(robot_io::emulator::ur_rtde_control). What is checked is what ur_rtde's own calls return
and what its receive interface reads back; no assertion depends on wall-clock speed (waits
poll with generous bounds, see common.py). Everything here runs on a simulated UR5e.

Order matters only through set-up: each test starts from a running script and an arm at
rest (setUp re-uploads the script when a test stopped it).
"""

import math
import unittest

import dashboard_client
import rtde_control
import rtde_receive

from common import HOST, MODE, RawRtde, wait_until

# Joint positions reached exactly by a synchronous moveJ [rad] (the model integrates to the
# profile's end point; rounding closes on the actual position every cycle).
EXACT_RAD = 1e-9


def rotvec_to_matrix(rx, ry, rz):
    """Rodrigues' formula: the rotation matrix of a rotation vector [rad]."""
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-15:
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    x, y, z = rx / angle, ry / angle, rz / angle
    c, s, t = math.cos(angle), math.sin(angle), 1.0 - math.cos(angle)
    return [[t * x * x + c, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, t * z * z + c]]


@unittest.skipUnless(MODE == "sim", "sim backend only: a recording cannot be commanded")
class Control(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.c = rtde_control.RTDEControlInterface(HOST)
        cls.r = rtde_receive.RTDEReceiveInterface(HOST)

    @classmethod
    def tearDownClass(cls):
        if cls.c.isProgramRunning():
            cls.c.stopScript()
        cls.c.disconnect()
        cls.r.disconnect()

    def setUp(self):
        if self.r.isProtectiveStopped():
            d = dashboard_client.DashboardClient(HOST)
            d.connect()
            d.unlockProtectiveStop()
            d.disconnect()
            wait_until(lambda: not self.r.isProtectiveStopped(), "protective stop released")
        if not self.c.isProgramRunning():
            # 1 STOPPED, 4 PAUSED: not on the way there any more.
            wait_until(lambda: self.r.getRuntimeState() in (1, 4), "program stopped or paused")
            self.assertTrue(self.c.reuploadScript())
            wait_until(self.c.isProgramRunning, "the script running again")
        wait_until(self.steady, "the arm at rest")

    def steady(self):
        return all(v == 0.0 for v in self.r.getActualQd())

    def test_construction_uploads_and_runs_the_script(self):
        self.assertTrue(self.c.isConnected())
        self.assertTrue(self.c.isProgramRunning())
        # Mode 7 RUNNING, runtime state 2 PLAYING, as ur_rtde's isProgramRunning reads it.
        self.assertEqual(self.r.getRobotMode(), 7)
        self.assertEqual(self.r.getRuntimeState(), 2)

    def test_move_j_synchronous_arrives_at_the_target(self):
        q0 = self.r.getActualQ()
        target = list(q0)
        target[0] += 0.25
        target[2] -= 0.1
        self.assertTrue(self.c.moveJ(target, 1.0, 1.4))
        q = self.r.getActualQ()
        for got, want in zip(q, target):
            self.assertAlmostEqual(got, want, delta=EXACT_RAD)
        self.assertTrue(self.steady())
        self.assertTrue(self.c.isSteady())
        self.assertTrue(self.c.moveJ(q0, 1.0, 1.4))
        for got, want in zip(self.r.getActualQ(), q0):
            self.assertAlmostEqual(got, want, delta=EXACT_RAD)

    def test_move_j_asynchronous_reports_progress_and_stop_j_ends_it(self):
        q0 = self.r.getActualQ()
        target = list(q0)
        target[0] += 0.6
        self.assertTrue(self.c.moveJ(target, 0.3, 0.5, True))
        # Running: ur_rtde returns the progress (0 for a single moveJ) while it runs.
        wait_until(lambda: self.c.getAsyncOperationProgress() >= 0, "async moveJ running")
        self.assertTrue(self.c.getAsyncOperationProgressEx().isAsyncOperationRunning())
        wait_until(lambda: self.r.getActualQ()[0] > q0[0] + 0.05, "the arm moving")
        self.c.stopJ(2.0, False)
        self.assertTrue(self.steady())
        self.assertLess(self.c.getAsyncOperationProgress(), 0)
        self.assertFalse(self.c.getAsyncOperationProgressEx().isAsyncOperationRunning())
        reached = self.r.getActualQ()[0]
        self.assertGreater(reached, q0[0] + 0.05)
        self.assertLess(reached, target[0] - 1e-3)
        self.assertTrue(self.c.moveJ(q0, 1.0, 1.4))

    def test_async_move_j_finishes_on_its_own(self):
        q0 = self.r.getActualQ()
        target = list(q0)
        target[1] += 0.1
        self.assertTrue(self.c.moveJ(target, 1.0, 1.4, True))
        wait_until(lambda: self.c.getAsyncOperationProgress() < 0, "async moveJ finished")
        for got, want in zip(self.r.getActualQ(), target):
            self.assertAlmostEqual(got, want, delta=EXACT_RAD)
        self.assertTrue(self.c.moveJ(q0, 1.0, 1.4))

    def test_servo_j_at_500_hz_tracks_and_servo_stop_ends_it(self):
        q0 = self.r.getActualQ()
        target = list(q0)
        for i in range(500):
            t0 = self.c.initPeriod()
            target[0] = q0[0] + 0.0002 * (i + 1)
            self.assertTrue(self.c.servoJ(target, 0.5, 0.5, 0.002, 0.1, 300))
            self.c.waitPeriod(t0)
        # The arm follows the last target (the model's servo filter converges on it).
        wait_until(lambda: abs(self.r.getActualQ()[0] - target[0]) < 1e-6, "servo converged")
        self.assertTrue(self.c.servoStop(2.0))
        self.assertTrue(self.steady())
        self.assertTrue(self.c.moveJ(q0, 1.0, 1.4))

    def test_speed_j_reaches_the_speed_and_speed_stop_stops(self):
        q0 = self.r.getActualQ()
        self.assertTrue(self.c.speedJ([0.2, 0.0, 0.0, 0.0, 0.0, -0.1], 1.0, 0.002))
        wait_until(lambda: abs(self.r.getActualQd()[0] - 0.2) < 1e-12, "speed reached")
        self.assertAlmostEqual(self.r.getActualQd()[5], -0.1, delta=1e-12)
        self.assertTrue(self.c.speedStop(2.0))
        self.assertTrue(self.steady())
        self.assertGreater(self.r.getActualQ()[0], q0[0])
        self.assertTrue(self.c.moveJ(q0, 1.0, 1.4))

    def test_stop_j_asynchronous_returns_and_the_arm_stops(self):
        self.assertTrue(self.c.speedJ([0.3, 0.0, 0.0, 0.0, 0.0, 0.0], 1.0, 0.002))
        wait_until(lambda: abs(self.r.getActualQd()[0] - 0.3) < 1e-12, "speed reached")
        q0 = self.r.getActualQ()
        self.c.stopJ(0.5, True)
        wait_until(lambda: self.c.getAsyncOperationProgress() < 0, "async stop finished")
        self.assertTrue(self.steady())
        # Braking from 0.3 rad/s at 0.5 rad/s² covers 0.09 rad (v²/2a) after the stop began,
        # which was after q0 was read: never less (a cycle's rounding aside).
        self.assertGreater(self.r.getActualQ()[0] - q0[0], 0.09 - 1e-3)

    def test_getters(self):
        # getStepTime is a real-time command: ur_rtde reads the register before the script
        # has written it on the next cycle (a race in ur_rtde itself), so the first call
        # may return the register's old value.
        wait_until(lambda: self.c.getStepTime() == 0.002, "getStepTime")
        self.assertTrue(self.c.isSteady())
        fk = self.c.getForwardKinematics()
        tcp = self.r.getActualTCPPose()
        for got, want in zip(fk, tcp):
            self.assertAlmostEqual(got, want, delta=1e-12)
        # With a TCP offset of 0.1 m along the flange's z axis: the flange's rotation applied.
        q = self.r.getActualQ()
        offset = self.c.getForwardKinematics(q, [0.0, 0.0, 0.1, 0.0, 0.0, 0.0])
        rot = rotvec_to_matrix(*tcp[3:])
        for k in range(3):
            self.assertAlmostEqual(offset[k], tcp[k] + 0.1 * rot[k][2], delta=1e-9)
        self.assertTrue(self.c.isJointsWithinSafetyLimits(q))
        self.assertFalse(self.c.isJointsWithinSafetyLimits([7.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
        self.assertEqual(self.c.getTCPOffset(), [0.0] * 6)
        wait_until(lambda: self.c.getJointTorques() == [0.0] * 6, "getJointTorques")

    def test_watchdog_fires_when_ur_rtde_goes_silent(self):
        self.assertTrue(self.c.setWatchdog(50.0))
        for _ in range(30):
            t0 = self.c.initPeriod()
            self.assertTrue(self.c.kickWatchdog())
            self.c.waitPeriod(t0)
        self.assertTrue(self.c.isProgramRunning())
        # Silence: no package for > 1/50 s stops the program.
        wait_until(lambda: not self.c.isProgramRunning(), "the watchdog stopping the script")
        self.assertEqual(self.r.getRuntimeState(), 1)
        self.assertFalse(self.c.moveJ(self.r.getActualQ(), 1.0, 1.4))

    def test_unmodelled_command_fails_and_stops_the_script(self):
        # moveL is Cartesian: refused as a controller refuses a script error, never waited for.
        self.assertFalse(self.c.moveL([0.3, 0.3, 0.3, 0.0, 3.14, 0.0], 0.1, 0.1))
        self.assertFalse(self.c.isProgramRunning())

    def test_protective_stop_fails_commands_until_released(self):
        self.c.triggerProtectiveStop()
        wait_until(self.r.isProtectiveStopped, "protective stop")
        self.assertFalse(self.c.moveJ(self.r.getActualQ(), 1.0, 1.4))
        d = dashboard_client.DashboardClient(HOST)
        d.connect()
        d.unlockProtectiveStop()
        wait_until(lambda: not self.r.isProtectiveStopped(), "protective stop released")
        d.play()
        d.disconnect()
        wait_until(self.c.isProgramRunning, "the script resumed")
        q0 = self.r.getActualQ()
        target = list(q0)
        target[3] += 0.05
        self.assertTrue(self.c.moveJ(target, 1.0, 1.4))
        self.assertAlmostEqual(self.r.getActualQ()[3], target[3], delta=EXACT_RAD)
        self.assertTrue(self.c.moveJ(q0, 1.0, 1.4))


@unittest.skipUnless(MODE == "sim", "sim backend only")
class UpperRange(unittest.TestCase):
    """FLAG_UPPER_RANGE_REGISTERS: the script's registers move to 24-47."""

    def test_upper_range_registers(self):
        flags = rtde_control.RTDEControlInterface.FLAG_UPLOAD_SCRIPT | \
            rtde_control.RTDEControlInterface.FLAG_UPPER_RANGE_REGISTERS
        c = rtde_control.RTDEControlInterface(HOST, 500.0, flags)
        r = rtde_receive.RTDEReceiveInterface(HOST)
        try:
            self.assertTrue(c.isProgramRunning())
            raw = RawRtde()
            raw.setup_outputs(["output_int_register_24", "output_int_register_0"])
            raw.start()
            # Ready for a command in register 24; register 0 untouched.
            wait_until(lambda: raw.sample() == [1, 0], "ready in output_int_register_24")
            raw.close()
            q0 = r.getActualQ()
            target = list(q0)
            target[4] += 0.1
            self.assertTrue(c.moveJ(target, 1.0, 1.4))
            self.assertAlmostEqual(r.getActualQ()[4], target[4], delta=EXACT_RAD)
            self.assertTrue(c.moveJ(q0, 1.0, 1.4))
        finally:
            c.stopScript()
            c.disconnect()
            r.disconnect()


if __name__ == "__main__":
    unittest.main()
