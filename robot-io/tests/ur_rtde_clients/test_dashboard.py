"""ur_rtde's DashboardClient against `hrc-adapt emulate --sim` (issue 11): every getter,
answered in PolyScope 5's format, and the action commands doing what the emulator models."""

import re
import unittest

import dashboard_client
import rtde_receive

from common import DASHBOARD_PORT, HOST, MODE, Dashboard, wait_until


@unittest.skipUnless(MODE == "sim", "sim backend only")
class DashboardGetters(unittest.TestCase):
    def setUp(self):
        self.d = dashboard_client.DashboardClient(HOST, DASHBOARD_PORT)
        self.d.connect()

    def tearDown(self):
        self.d.disconnect()

    def test_every_getter_answers_in_polyscope_5_format(self):
        d = self.d
        self.assertTrue(d.isConnected())
        # ur_rtde returns the version it parsed out of "URSoftware 5.x.y.z".
        self.assertRegex(d.polyscopeVersion(), r"^5\.\d+\.\d+\.\d+$")
        self.assertRegex(d.getSerialNumber(), r"^\d{11}$")
        self.assertEqual(d.getRobotModel(), "UR5")
        # Independent of the other tests' order (a program may be loaded already).
        self.assertRegex(d.programState(), r"^STOPPED \S+$")
        self.assertFalse(d.running())
        self.assertEqual(d.safetymode(), "Safetymode: NORMAL")
        self.assertEqual(d.safetystatus(), "Safetystatus: NORMAL")
        self.assertEqual(d.robotmode(), "Robotmode: RUNNING")
        self.assertRegex(d.getLoadedProgram(), r"^(No program loaded|Loaded program: \S+)$")
        self.assertTrue(d.isInRemoteControl())

    def test_raw_replies_match_ur_documentation(self):
        raw = Dashboard()
        try:
            self.assertEqual(raw.greeting, "Connected: Universal Robots Dashboard Server")
            self.assertRegex(raw.ask("version"), r"^5\.\d+\.\d+\.\d+$")
            self.assertRegex(raw.ask("PolyscopeVersion"), r"^URSoftware 5\.\d+\.\d+\.\d+$")
            self.assertRegex(raw.ask("isProgramSaved"), r"^(True|False) \S+$")
            self.assertEqual(raw.ask("popup hello"), "showing popup")
            self.assertEqual(raw.ask("close popup"), "closing popup")
            self.assertEqual(raw.ask("addToLog a line"), "Added log message")
            self.assertEqual(raw.ask("get operational mode"), "NONE")
            self.assertEqual(raw.ask("set operational mode manual"), "Operational mode 'manual' is set")
            self.assertEqual(raw.ask("get operational mode"), "MANUAL")
            self.assertTrue(raw.ask("clear operational mode").startswith("No longer controlling"))
            self.assertEqual(raw.ask("load installation default.installation"),
                             "Loading installation: default.installation")
            self.assertEqual(raw.ask("dance"), "could not understand: 'dance'")
        finally:
            raw.close()


@unittest.skipUnless(MODE == "sim", "sim backend only")
class DashboardActions(unittest.TestCase):
    """Runs in order: load, play, pause, stop, power off, power on, brake release."""

    def test_actions_change_the_modelled_state(self):
        d = dashboard_client.DashboardClient(HOST, DASHBOARD_PORT)
        d.connect()
        r = rtde_receive.RTDEReceiveInterface(HOST, 500.0, ["timestamp", "robot_mode", "runtime_state"])
        try:
            d.loadURP("/programs/handover.urp")
            self.assertEqual(d.getLoadedProgram(), "Loaded program: /programs/handover.urp")
            self.assertEqual(d.programState(), "STOPPED handover.urp")
            self.assertTrue(d.isProgramSaved())
            d.play()
            wait_until(d.running, "the program running")
            self.assertEqual(r.getRuntimeState(), 2, "PLAYING") if r.getRuntimeState() == 2 else \
                wait_until(lambda: r.getRuntimeState() == 2, "runtime_state PLAYING")
            self.assertEqual(d.programState(), "PLAYING handover.urp")
            d.pause()
            wait_until(lambda: d.programState() == "PAUSED handover.urp", "PAUSED")
            d.stop()
            wait_until(lambda: d.programState() == "STOPPED handover.urp", "STOPPED")
            self.assertFalse(d.running())
            d.powerOff()
            wait_until(lambda: r.getRobotMode() == 3, "robot_mode POWER_OFF")
            self.assertEqual(d.robotmode(), "Robotmode: POWER_OFF")
            d.powerOn()
            wait_until(lambda: r.getRobotMode() == 5, "robot_mode IDLE")
            d.brakeRelease()
            wait_until(lambda: r.getRobotMode() == 7, "robot_mode RUNNING")
            d.closeSafetyPopup()
            d.closePopup()
            d.popup("from ur_rtde")
            d.addToLog("from ur_rtde")
            # No protective stop is active: ur_rtde reports the refusal as an error.
            with self.assertRaises(RuntimeError):
                d.unlockProtectiveStop()
        finally:
            r.disconnect()
            d.disconnect()


if __name__ == "__main__":
    unittest.main()
