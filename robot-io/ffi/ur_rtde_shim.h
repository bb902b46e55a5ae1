/* hrc-adapt's C shim over SDU's ur_rtde 1.6.5 (robot-io feature `ur-rtde`).
 *
 * Opaque handles, plain arrays and integer status: no C++ type and no C++ exception crosses
 * this interface. Every function returns URS_OK (0) or a negative status; the message of the
 * last failure on a handle is kept in the handle (urs_*_last_error). A handle is used by one
 * thread at a time (the Rust side is !Sync). */
#ifndef HRC_UR_RTDE_SHIM_H
#define HRC_UR_RTDE_SHIM_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define URS_OK 0
/* A ur_rtde call threw (the message is in the handle, or in `err` for a constructor). */
#define URS_EXCEPTION (-1)
/* ur_rtde returned false (a command it did not take). */
#define URS_REJECTED (-2)
/* The interface reports it is not connected. */
#define URS_DISCONNECTED (-3)
/* A null handle or argument. */
#define URS_BAD_ARGUMENT (-4)

typedef struct urs_receive urs_receive;
typedef struct urs_control urs_control;

/* The state read each cycle, the fields of robot_io::RobotState. */
typedef struct urs_state {
  double timestamp_s;
  double actual_q[6];
  double actual_qd[6];
  double target_q[6];
  double target_qd[6];
  double actual_tcp_pose[6];
  double actual_tcp_speed[6];
  double speed_scaling;
  double target_speed_fraction;
  int32_t robot_mode;
  int32_t safety_mode;
  uint32_t runtime_state;
  uint32_t robot_status_bits;
  uint32_t safety_status_bits;
} urs_state;

/* RTDEReceiveInterface(host, frequency [Hz], the fields of urs_state). On failure returns NULL
 * and writes a NUL-terminated message into err[0..err_len). */
urs_receive *urs_receive_new(const char *host, double frequency_hz, char *err, size_t err_len);
void urs_receive_free(urs_receive *h);
/* The newest sample, all fields from one package (read from ur_rtde's state object field by
 * field, again while a package arrives in between, at most 8 times; URS_REJECTED if the state
 * changed during each, or a field is missing). Allocates nothing. */
int urs_receive_read(urs_receive *h, urs_state *out);
/* 1 connected, 0 not, negative on failure. */
int urs_receive_is_connected(urs_receive *h);
int urs_receive_reconnect(urs_receive *h);
const char *urs_receive_last_error(const urs_receive *h);

/* RTDEControlInterface(host, frequency [Hz], FLAG_UPLOAD_SCRIPT | FLAG_UPPER_RANGE_REGISTERS
 * when upper_range != 0). NULL and a message in err on failure. */
urs_control *urs_control_new(const char *host, double frequency_hz, int upper_range, char *err,
                             size_t err_len);
void urs_control_free(urs_control *h);
/* servoJ(q [rad], speed, acceleration (unused by UR), time [s], lookahead [s], gain). */
int urs_control_servo_j(urs_control *h, const double q[6], double time_s, double lookahead_s,
                        double gain);
/* speedJ(qd [rad/s], acceleration [rad/s^2], time [s]). */
int urs_control_speed_j(urs_control *h, const double qd[6], double acc, double time_s);
int urs_control_servo_stop(urs_control *h, double decel);
int urs_control_speed_stop(urs_control *h, double decel);
/* stopJ(decel [rad/s^2], asynchronous): asynchronous != 0 returns without waiting for the stop. */
int urs_control_stop_j(urs_control *h, double decel, int asynchronous);
int urs_control_stop_script(urs_control *h);
/* initPeriod: the start of a cycle as steady_clock nanoseconds. */
int urs_control_init_period(urs_control *h, int64_t *t_start_ns);
/* waitPeriod(t_start): sleeps/spins to the end of the period given at construction. */
int urs_control_wait_period(urs_control *h, int64_t t_start_ns);
int urs_control_is_connected(urs_control *h);
int urs_control_is_program_running(urs_control *h);
int urs_control_reconnect(urs_control *h);
const char *urs_control_last_error(const urs_control *h);

#ifdef __cplusplus
}
#endif
#endif
