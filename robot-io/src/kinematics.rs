//! UR5e kinematics shared by the simulator, the controller and the supervisor (being written: issue 4).
