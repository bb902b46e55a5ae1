"""ur_rtde's RTDEControlInterface is out of the emulator's scope for now (issue 11, point 2):
constructing one must fail clearly, never hang."""

import unittest

import rtde_control

from common import HOST, MODE


@unittest.skipUnless(MODE == "sim", "sim backend only")
class Control(unittest.TestCase):
    def test_construction_fails_with_an_error(self):
        with self.assertRaises(RuntimeError):
            rtde_control.RTDEControlInterface(HOST)


if __name__ == "__main__":
    unittest.main()
