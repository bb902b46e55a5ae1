"""ur_rtde's RTDEIOInterface against `hrc-adapt emulate --sim` (issue 11): registers and
outputs written through ur_rtde and read back (input registers with a plain RTDE reader of
ours, since ur_rtde's receive interface reads output registers only; digital and analog outputs
with ur_rtde's own receive interface)."""

import unittest

import rtde_io
import rtde_receive

from common import HOST, MODE, RawRtde, wait_until


@unittest.skipUnless(MODE == "sim", "sim backend only")
class Io(unittest.TestCase):
    def setUp(self):
        self.io = rtde_io.RTDEIOInterface(HOST)

    def tearDown(self):
        self.io.disconnect()

    def test_input_registers_written_are_read_back(self):
        self.assertTrue(self.io.setInputIntRegister(18, 4711))
        self.assertTrue(self.io.setInputIntRegister(22, -5))
        self.assertTrue(self.io.setInputDoubleRegister(19, 2.25))
        raw = RawRtde()
        try:
            _, types = raw.setup_outputs(["input_int_register_18", "input_int_register_22",
                                          "input_double_register_19"])
            self.assertEqual(types, ["INT32", "INT32", "DOUBLE"])
            raw.start()
            wait_until(lambda: raw.sample() == [4711, -5, 2.25], "the registers written")
            self.assertTrue(self.io.setInputIntRegister(18, 7))
            wait_until(lambda: raw.sample()[0] == 7, "the register rewritten")
        finally:
            raw.close()

    def test_digital_and_analog_outputs_are_echoed(self):
        self.assertTrue(self.io.setStandardDigitalOut(3, True))
        self.assertTrue(self.io.setConfigurableDigitalOut(1, True))
        self.assertTrue(self.io.setToolDigitalOut(0, True))
        self.assertTrue(self.io.setAnalogOutputVoltage(0, 0.5))
        r = rtde_receive.RTDEReceiveInterface(HOST, 500.0, [
            "timestamp", "actual_digital_output_bits", "standard_analog_output0"])
        try:
            want = (1 << 3) | (1 << 9) | (1 << 16)
            wait_until(lambda: r.getActualDigitalOutputBits() == want, "digital outputs")
            self.assertTrue(r.getDigitalOutState(3))
            self.assertFalse(r.getDigitalOutState(2))
            wait_until(lambda: abs(r.getStandardAnalogOutput0() - 5.0) < 1e-9, "AO0 at 5 V")
            self.assertTrue(self.io.setStandardDigitalOut(3, False))
            wait_until(lambda: not r.getDigitalOutState(3), "digital output 3 cleared")
            self.assertTrue(r.getDigitalOutState(9), "the other outputs stay")
        finally:
            r.disconnect()

    def test_speed_slider_sets_the_target_speed_fraction(self):
        self.assertTrue(self.io.setSpeedSlider(0.4))
        r = rtde_receive.RTDEReceiveInterface(HOST, 500.0, ["timestamp", "target_speed_fraction"])
        try:
            wait_until(lambda: abs(r.getTargetSpeedFraction() - 0.4) < 1e-12, "slider at 0.4")
            self.assertTrue(self.io.setSpeedSlider(1.0))
            wait_until(lambda: r.getTargetSpeedFraction() == 1.0, "slider back at 1")
        finally:
            r.disconnect()


if __name__ == "__main__":
    unittest.main()
