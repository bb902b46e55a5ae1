// hrc-adapt's C shim over ur_rtde 1.6.5: see ur_rtde_shim.h. Every entry point catches every
// exception; a message is kept in the handle (a fixed buffer, so recording it allocates no
// more than what() did).
#pragma GCC visibility push(default)
#include "ur_rtde_shim.h"
#pragma GCC visibility pop

#include <ur_rtde/rtde_control_interface.h>
#include <ur_rtde/rtde_receive_interface.h>

#include <chrono>
#include <cstring>
#include <exception>
#include <memory>
#include <string>
#include <vector>

namespace {

constexpr size_t kMsg = 512;

void put(char *dst, size_t len, const char *msg) {
  if (dst == nullptr || len == 0) return;
  std::strncpy(dst, msg, len - 1);
  dst[len - 1] = '\0';
}

// Copies at most 6 values of v into out (zeros past its end).
void copy6(const std::vector<double> &v, double out[6]) {
  for (size_t i = 0; i < 6; ++i) out[i] = i < v.size() ? v[i] : 0.0;
}

}  // namespace

// The field names of one read, built once: ur_rtde's getters take the name as a `const char*`
// literal, which becomes a std::string (allocated past 15 characters) on every call, and
// return their vector by value. The shim reads ur_rtde's RobotState directly with these
// keys into vectors of its own, which keep their storage: a read allocates nothing.
struct Keys {
  std::string timestamp = "timestamp", actual_q = "actual_q", actual_qd = "actual_qd",
              target_q = "target_q", target_qd = "target_qd", tcp_pose = "actual_TCP_pose",
              tcp_speed = "actual_TCP_speed", speed_scaling = "speed_scaling",
              target_speed_fraction = "target_speed_fraction", robot_mode = "robot_mode",
              safety_mode = "safety_mode", runtime_state = "runtime_state",
              robot_status_bits = "robot_status_bits", safety_status_bits = "safety_status_bits";
};

struct urs_receive {
  std::unique_ptr<ur_rtde::RTDEReceiveInterface> rx;
  Keys keys;
  std::vector<double> v = std::vector<double>(6, 0.0);  // reused by every vector field
  char err[kMsg] = {0};
};

struct urs_control {
  std::unique_ptr<ur_rtde::RTDEControlInterface> ctl;
  std::vector<double> buf = std::vector<double>(6, 0.0);  // reused: servoJ/speedJ take a vector
  char err[kMsg] = {0};
};

#define URS_GUARD(h, body)                                  \
  if ((h) == nullptr) return URS_BAD_ARGUMENT;              \
  try {                                                     \
    body                                                    \
  } catch (const std::exception &e) {                       \
    put((h)->err, kMsg, e.what());                          \
    return URS_EXCEPTION;                                   \
  } catch (...) {                                           \
    put((h)->err, kMsg, "unknown C++ exception in ur_rtde"); \
    return URS_EXCEPTION;                                   \
  }

// A command on a control interface whose link is down: ur_rtde's stopJ, servoStop and
// speedStop wait for the script's "done" on the last state received, which a dead controller
// never changes, for up to UR_EXECUTION_TIMEOUT (300 s); servoJ and speedJ wait up to 3 s for
// "ready". Checked first, so a lost link is an error at once (seen: a trial whose emulator
// was killed blocked in stopJ).
#define URS_REQUIRE_LINK(h)                                          \
  if (!(h)->ctl->isConnected()) {                                   \
    put((h)->err, kMsg, "RTDEControlInterface is not connected");   \
    return URS_DISCONNECTED;                                         \
  }

extern "C" {

urs_receive *urs_receive_new(const char *host, double frequency_hz, char *err, size_t err_len) {
  if (host == nullptr) {
    put(err, err_len, "null host");
    return nullptr;
  }
  try {
    std::vector<std::string> vars = {"timestamp",        "actual_q",
                                     "actual_qd",        "target_q",
                                     "target_qd",        "actual_TCP_pose",
                                     "actual_TCP_speed", "speed_scaling",
                                     "target_speed_fraction", "robot_mode",
                                     "safety_mode",      "runtime_state",
                                     "robot_status_bits", "safety_status_bits"};
    auto h = std::make_unique<urs_receive>();
    h->rx = std::make_unique<ur_rtde::RTDEReceiveInterface>(std::string(host), frequency_hz, vars);
    return h.release();
  } catch (const std::exception &e) {
    put(err, err_len, e.what());
  } catch (...) {
    put(err, err_len, "unknown C++ exception in RTDEReceiveInterface()");
  }
  return nullptr;
}

void urs_receive_free(urs_receive *h) {
  try {
    delete h;
  } catch (...) {
  }
}

// The body of urs_receive_read (outside URS_GUARD: a macro argument cannot hold its commas).
static int read_state(urs_receive *h, urs_state *out) {
  auto &rx = *h->rx;
  if (!rx.isConnected()) {
    put(h->err, kMsg, "RTDEReceiveInterface is not connected");
    return URS_DISCONNECTED;
  }
  // ur_rtde's own state object (replaced on a reconnect, so taken each read). Its receive
  // thread writes a whole package under the state mutex, but getStateData locks it for one
  // field: a package arriving between two fields would mix two samples (seen under load: a
  // row with one sample's timestamp and the next one's joints). Each package has a new
  // controller timestamp, so the fields are one sample when the timestamp read after them is
  // the one read before them; otherwise read again. A missing field (not in the recipe) is
  // an error, not a zero.
  const auto &st = rx.robot_state();
  if (!st) {
    put(h->err, kMsg, "RTDEReceiveInterface has no state yet");
    return URS_DISCONNECTED;
  }
  const Keys &k = h->keys;
  std::vector<double> &v = h->v;
  bool ok = true;
  auto vec6 = [&](const std::string &key, double dst[6]) {
    ok = st->getStateData(key, v) && ok;
    copy6(v, dst);
  };
  for (int attempt = 0; attempt < 8; ++attempt) {
    ok = true;
    double t0 = 0.0, t1 = 0.0;
    int32_t robot_mode = 0, safety_mode = 0;
    uint32_t runtime_state = 0, robot_status = 0, safety_status = 0;
    ok = st->getStateData(k.timestamp, t0) && ok;
    vec6(k.actual_q, out->actual_q);
    vec6(k.actual_qd, out->actual_qd);
    vec6(k.target_q, out->target_q);
    vec6(k.target_qd, out->target_qd);
    vec6(k.tcp_pose, out->actual_tcp_pose);
    vec6(k.tcp_speed, out->actual_tcp_speed);
    ok = st->getStateData(k.speed_scaling, out->speed_scaling) && ok;
    ok = st->getStateData(k.target_speed_fraction, out->target_speed_fraction) && ok;
    ok = st->getStateData(k.robot_mode, robot_mode) && ok;
    ok = st->getStateData(k.safety_mode, safety_mode) && ok;
    ok = st->getStateData(k.runtime_state, runtime_state) && ok;
    ok = st->getStateData(k.robot_status_bits, robot_status) && ok;
    ok = st->getStateData(k.safety_status_bits, safety_status) && ok;
    ok = st->getStateData(k.timestamp, t1) && ok;
    if (!ok) {
      put(h->err, kMsg, "a field of the receive recipe is missing from ur_rtde's state");
      return URS_REJECTED;
    }
    out->robot_mode = robot_mode;
    out->safety_mode = safety_mode;
    out->runtime_state = runtime_state;
    out->robot_status_bits = robot_status;
    out->safety_status_bits = safety_status;
    out->timestamp_s = t0;
    if (t1 == t0) return URS_OK;
  }
  put(h->err, kMsg, "the state changed during each of 8 reads (no consistent sample)");
  return URS_REJECTED;
}

int urs_receive_read(urs_receive *h, urs_state *out) {
  if (out == nullptr) return URS_BAD_ARGUMENT;
  URS_GUARD(h, { return read_state(h, out); })
}

int urs_receive_is_connected(urs_receive *h) { URS_GUARD(h, { return h->rx->isConnected() ? 1 : 0; }) }

int urs_receive_reconnect(urs_receive *h) {
  URS_GUARD(h, {
    if (h->rx->reconnect()) return URS_OK;
    put(h->err, kMsg, "RTDEReceiveInterface::reconnect returned false");
    return URS_REJECTED;
  })
}

const char *urs_receive_last_error(const urs_receive *h) { return h == nullptr ? "null handle" : h->err; }

urs_control *urs_control_new(const char *host, double frequency_hz, int upper_range, char *err,
                             size_t err_len) {
  if (host == nullptr) {
    put(err, err_len, "null host");
    return nullptr;
  }
  try {
    uint16_t flags = ur_rtde::RTDEControlInterface::FLAG_UPLOAD_SCRIPT;
    if (upper_range != 0) flags |= ur_rtde::RTDEControlInterface::FLAG_UPPER_RANGE_REGISTERS;
    auto h = std::make_unique<urs_control>();
    h->ctl = std::make_unique<ur_rtde::RTDEControlInterface>(std::string(host), frequency_hz, flags);
    return h.release();
  } catch (const std::exception &e) {
    put(err, err_len, e.what());
  } catch (...) {
    put(err, err_len, "unknown C++ exception in RTDEControlInterface()");
  }
  return nullptr;
}

void urs_control_free(urs_control *h) {
  if (h == nullptr) return;
  try {
    // Not on a dead link: stopScript then waits for the program to stop on the last state
    // received, up to 300 s (see URS_REQUIRE_LINK).
    if (h->ctl && h->ctl->isConnected()) h->ctl->stopScript();
  } catch (...) {
  }
  try {
    delete h;
  } catch (...) {
  }
}

static int taken(urs_control *h, bool ok, const char *what) {
  if (ok) return URS_OK;
  put(h->err, kMsg, what);
  return URS_REJECTED;
}

int urs_control_servo_j(urs_control *h, const double q[6], double time_s, double lookahead_s,
                        double gain) {
  if (q == nullptr) return URS_BAD_ARGUMENT;
  URS_GUARD(h, {
    URS_REQUIRE_LINK(h);
    for (size_t i = 0; i < 6; ++i) h->buf[i] = q[i];
    // speed and acceleration are not used by UR's servoj (ur_rtde passes them on).
    return taken(h, h->ctl->servoJ(h->buf, 0.0, 0.0, time_s, lookahead_s, gain),
                 "RTDEControlInterface::servoJ returned false");
  })
}

int urs_control_speed_j(urs_control *h, const double qd[6], double acc, double time_s) {
  if (qd == nullptr) return URS_BAD_ARGUMENT;
  URS_GUARD(h, {
    URS_REQUIRE_LINK(h);
    for (size_t i = 0; i < 6; ++i) h->buf[i] = qd[i];
    return taken(h, h->ctl->speedJ(h->buf, acc, time_s), "RTDEControlInterface::speedJ returned false");
  })
}

int urs_control_servo_stop(urs_control *h, double decel) {
  URS_GUARD(h, {
    URS_REQUIRE_LINK(h);
    return taken(h, h->ctl->servoStop(decel), "RTDEControlInterface::servoStop returned false");
  })
}

int urs_control_speed_stop(urs_control *h, double decel) {
  URS_GUARD(h, {
    URS_REQUIRE_LINK(h);
    return taken(h, h->ctl->speedStop(decel), "RTDEControlInterface::speedStop returned false");
  })
}

int urs_control_stop_j(urs_control *h, double decel, int asynchronous) {
  URS_GUARD(h, {
    URS_REQUIRE_LINK(h);
    h->ctl->stopJ(decel, asynchronous != 0);
    return URS_OK;
  })
}

int urs_control_stop_script(urs_control *h) {
  URS_GUARD(h, {
    URS_REQUIRE_LINK(h);
    h->ctl->stopScript();
    return URS_OK;
  })
}

int urs_control_init_period(urs_control *h, int64_t *t_start_ns) {
  if (t_start_ns == nullptr) return URS_BAD_ARGUMENT;
  URS_GUARD(h, {
    auto t = h->ctl->initPeriod();
    *t_start_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
    return URS_OK;
  })
}

int urs_control_wait_period(urs_control *h, int64_t t_start_ns) {
  URS_GUARD(h, {
    std::chrono::steady_clock::time_point t{std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::nanoseconds(t_start_ns))};
    h->ctl->waitPeriod(t);
    return URS_OK;
  })
}

int urs_control_is_connected(urs_control *h) { URS_GUARD(h, { return h->ctl->isConnected() ? 1 : 0; }) }

int urs_control_is_program_running(urs_control *h) {
  URS_GUARD(h, { return h->ctl->isProgramRunning() ? 1 : 0; })
}

int urs_control_reconnect(urs_control *h) {
  URS_GUARD(h, {
    if (h->ctl->reconnect()) return URS_OK;
    put(h->err, kMsg, "RTDEControlInterface::reconnect returned false");
    return URS_REJECTED;
  })
}

const char *urs_control_last_error(const urs_control *h) { return h == nullptr ? "null handle" : h->err; }

}  // extern "C"
