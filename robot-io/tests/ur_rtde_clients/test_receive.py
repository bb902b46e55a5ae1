"""ur_rtde's RTDEReceiveInterface against `hrc-adapt emulate --sim` (issue 11)."""

import math
import unittest

import rtde_receive

from common import HOST, MODE, wait_until

CYCLE_S = 0.002
# UR5e joint position limits [rad].
Q_LIMIT = 2 * math.pi + 1e-9


def distinct_timestamps(r, n):
    seen = []
    def more():
        t = r.getTimestamp()
        if not seen or t != seen[-1]:
            seen.append(t)
        return len(seen) >= n
    wait_until(more, "%d distinct timestamps" % n, poll=0.0005)
    return seen


def assert_steps_are_cycles(test, stamps, every):
    for a, b in zip(stamps, stamps[1:]):
        step = b - a
        test.assertGreater(step, 0.0, "timestamps go back: %r -> %r" % (a, b))
        k = step / (CYCLE_S * every)
        test.assertAlmostEqual(k, round(k), delta=1e-6,
                               msg="step %.9f s is not a multiple of %d cycles" % (step, every))


@unittest.skipUnless(MODE == "sim", "sim backend only")
class ReceiveSim(unittest.TestCase):
    def test_default_field_list_serves_every_getter_consistently(self):
        r = rtde_receive.RTDEReceiveInterface(HOST)
        try:
            self.assertTrue(r.isConnected())
            stamps = distinct_timestamps(r, 20)
            assert_steps_are_cycles(self, stamps, 1)
            q = r.getActualQ()
            self.assertEqual(len(q), 6)
            for x in q + r.getTargetQ():
                self.assertLessEqual(abs(x), Q_LIMIT)
            # At rest after start-up: target and actual agree, and the TCP pose is the same
            # computed from either.
            for a, b in zip(r.getActualTCPPose(), r.getTargetTCPPose()):
                self.assertAlmostEqual(a, b, places=6)
            x, y, z = r.getActualTCPPose()[:3]
            # d1 + a2 + a3 + d4 + d5 + d6 = 1.27 m: no flange pose is farther from the base.
            self.assertLess(math.sqrt(x * x + y * y + z * z), 1.28, "beyond a UR5e's reach")
            self.assertEqual(r.getRobotMode(), 7, "RUNNING")
            self.assertEqual(r.getSafetyMode(), 1, "NORMAL")
            self.assertEqual(r.getJointMode(), [253] * 6, "every joint RUNNING")
            for t in r.getJointTemperatures():
                self.assertGreaterEqual(t, 20.0)
                self.assertLess(t, 80.0)
            for i in r.getActualCurrent() + r.getTargetCurrent():
                self.assertTrue(math.isfinite(i))
                self.assertLess(abs(i), 20.0, "current beyond a UR5e joint's range")
            self.assertAlmostEqual(r.getActualMainVoltage(), 48.0)
            self.assertAlmostEqual(r.getActualRobotVoltage(), 48.0)
            self.assertEqual(r.getActualJointVoltage(), [48.0] * 6)
            self.assertGreater(r.getActualRobotCurrent(), 0.0, "a powered arm draws current")
            acc = r.getActualToolAccelerometer()
            self.assertAlmostEqual(math.sqrt(sum(a * a for a in acc)), 9.81, places=3)
            self.assertGreater(r.getActualExecutionTime(), 0.0)
            self.assertGreaterEqual(r.getSpeedScaling(), 0.0)
            self.assertLessEqual(r.getSpeedScaling(), 1.0)
            self.assertEqual(r.getPayload(), 0.0)
            self.assertEqual(len(r.getPayloadCog()), 3)
            self.assertEqual(len(r.getFtRawWrench()), 6)
            self.assertFalse(r.isProtectiveStopped())
            self.assertFalse(r.isEmergencyStopped())
            self.assertEqual(r.getOutputIntRegister(18), 0)
            self.assertEqual(r.getOutputDoubleRegister(18), 0.0)
        finally:
            r.disconnect()

    def test_explicit_short_list_streams_at_500_hz(self):
        r = rtde_receive.RTDEReceiveInterface(HOST, 500.0, ["timestamp", "actual_q"])
        try:
            assert_steps_are_cycles(self, distinct_timestamps(r, 30), 1)
            for x in r.getActualQ():
                self.assertLessEqual(abs(x), Q_LIMIT)
        finally:
            r.disconnect()

    def test_explicit_list_at_125_hz_steps_four_cycles(self):
        r = rtde_receive.RTDEReceiveInterface(HOST, 125.0, ["timestamp", "robot_mode"])
        try:
            assert_steps_are_cycles(self, distinct_timestamps(r, 10), 4)
            self.assertEqual(r.getRobotMode(), 7)
        finally:
            r.disconnect()

    def test_explicit_long_list(self):
        names = ["timestamp", "target_q", "target_qd", "target_qdd", "target_current",
                 "target_moment", "actual_q", "actual_qd", "actual_current",
                 "joint_control_output", "actual_TCP_pose", "actual_TCP_speed",
                 "actual_TCP_force", "target_TCP_pose", "target_TCP_speed",
                 "actual_digital_input_bits", "joint_temperatures", "actual_execution_time",
                 "robot_mode", "joint_mode", "safety_mode", "actual_tool_accelerometer",
                 "speed_scaling", "target_speed_fraction", "actual_momentum",
                 "actual_main_voltage", "actual_robot_voltage", "actual_robot_current",
                 "actual_joint_voltage", "actual_digital_output_bits", "runtime_state",
                 "standard_analog_input0", "standard_analog_input1",
                 "standard_analog_output0", "standard_analog_output1", "robot_status_bits",
                 "safety_status_bits", "output_int_register_18", "output_double_register_18",
                 "ft_raw_wrench", "payload", "payload_cog", "payload_inertia"]
        r = rtde_receive.RTDEReceiveInterface(HOST, 500.0, names)
        try:
            assert_steps_are_cycles(self, distinct_timestamps(r, 10), 1)
            self.assertEqual(r.getJointMode(), [253] * 6)
            self.assertEqual(r.getActualJointVoltage(), [48.0] * 6)
            self.assertEqual(r.getActualTCPForce(), [0.0] * 6)
            # Currents are torque / torque constant: their sign follows the moment's.
            for i, m in zip(r.getTargetCurrent(), r.getTargetMoment()):
                self.assertGreaterEqual(i * m, 0.0)
        finally:
            r.disconnect()


@unittest.skipUnless(MODE == "trace", "trace backend only")
class ReceiveTrace(unittest.TestCase):
    def rows(self):
        import os
        path = os.environ["HRC_EMU_TRACE"]
        with open(path) as f:
            header = f.readline().split()
            return header, [list(map(float, line.split())) for line in f if line.strip()]

    def test_explicit_list_replays_recorded_rows_bit_for_bit(self):
        header, rows = self.rows()
        cols = [header.index("actual_q_%d" % i) for i in range(6)]
        recorded = {tuple(row[c] for c in cols) for row in rows}
        stamps = {row[header.index("timestamp")] for row in rows}
        r = rtde_receive.RTDEReceiveInterface(HOST, 500.0, ["timestamp", "actual_q"])
        try:
            seen = set()
            def more():
                seen.add(r.getTimestamp())
                q = tuple(r.getActualQ())
                self.assertIn(q, recorded, "a joint vector the trace does not hold")
                return len(seen) >= 3
            wait_until(more, "three recorded rows")
            self.assertTrue(seen <= stamps, "timestamps the trace does not hold: %r" % (seen - stamps))
        finally:
            r.disconnect()

    def test_default_list_is_refused_for_fields_the_trace_lacks(self):
        # record.py's default recipe lacks some of ur_rtde's default fields: ur_rtde names
        # them (as a controller answers NOT_FOUND) instead of crashing.
        header, _ = self.rows()
        try:
            r = rtde_receive.RTDEReceiveInterface(HOST)
        except RuntimeError as e:
            self.assertIn("not found by the controller", str(e))
        else:
            # The trace has every default field: then the getters read recorded values.
            try:
                self.assertIn("timestamp", header)
                self.assertEqual(len(r.getActualQ()), 6)
            finally:
                r.disconnect()


if __name__ == "__main__":
    unittest.main()
