/* Counts the malloc calls of the shim's calls on the calling thread, against an emulator (or
 * a controller) on HOST (default 127.0.0.1): 1000 urs_receive_read, then 500 servoJ that hold
 * the arm where it is. An executable's own malloc interposes on librtde's and libstdc++'s,
 * which the Rust counting allocator cannot see. Exit status 1 when a read allocates (the
 * shim's reads must not: robot-io's ur_rtde_robot module docs); servoJ is reported, not
 * judged (ur_rtde builds its command package in vectors; the shim cannot avoid it).
 * Run by scripts/test-ur-rtde against `hrc-adapt emulate --sim`; by hand:
 *
 *   g++ -std=c++17 -D_GLIBCXX_USE_CXX11_ABI=0 -c robot-io/ffi/ur_rtde_shim.cpp \
 *       -Irobot-io/ffi/include -I"$UR_RTDE_INCLUDE" -o /tmp/shim.o
 *   gcc -c robot-io/ffi/tools/alloc_count.c -Irobot-io/ffi -o /tmp/count.o
 *   g++ /tmp/count.o /tmp/shim.o -L"$UR_RTDE_LIB_DIR" -lrtde -Wl,-rpath,"$UR_RTDE_LIB_DIR" -o /tmp/count
 *   /tmp/count [HOST]
 */
#define _GNU_SOURCE
#include "ur_rtde_shim.h"
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

extern void *__libc_malloc(size_t);
static __thread int counting = 0;
static __thread long count = 0;
void *malloc(size_t n) {
  if (counting) count++;
  return __libc_malloc(n);
}

int main(int argc, char **argv) {
  const char *host = argc > 1 ? argv[1] : "127.0.0.1";
  char e[512];
  urs_receive *rx = urs_receive_new(host, 500, e, sizeof e);
  if (!rx) {
    printf("alloc_count: RTDEReceiveInterface: %s\n", e);
    return 2;
  }
  urs_state s;
  usleep(200000);
  for (int i = 0; i < 10; i++) urs_receive_read(rx, &s);
  long reads = 1000, failed = 0;
  count = 0;
  counting = 1;
  for (long i = 0; i < reads; i++) {
    if (urs_receive_read(rx, &s) != URS_OK) failed++;
    usleep(2000);
  }
  counting = 0;
  long read_mallocs = count;
  printf("alloc_count: %ld malloc calls over %ld urs_receive_read (%.2f per read; %ld failed), t = %.3f s\n",
         read_mallocs, reads, (double)read_mallocs / reads, failed, s.timestamp_s);

  urs_control *ctl = urs_control_new(host, 500, 0, e, sizeof e);
  if (!ctl) {
    printf("alloc_count: RTDEControlInterface: %s\n", e);
    urs_receive_free(rx);
    return 2;
  }
  urs_receive_read(rx, &s);
  long sends = 500, refused = 0;
  for (int i = 0; i < 10; i++) urs_control_servo_j(ctl, s.actual_q, 0.002, 0.1, 300);
  count = 0;
  counting = 1;
  for (long i = 0; i < sends; i++) {
    if (urs_control_servo_j(ctl, s.actual_q, 0.002, 0.1, 300) != URS_OK) refused++;
    usleep(2000);
  }
  counting = 0;
  printf("alloc_count: %ld malloc calls over %ld servoJ (%.2f per call; %ld refused; reported, not judged)\n",
         count, sends, (double)count / sends, refused);
  urs_control_stop_j(ctl, 3.0, 1);
  urs_control_free(ctl);
  urs_receive_free(rx);
  if (failed > 0 || refused > 0) {
    printf("alloc_count: calls failed\n");
    return 1;
  }
  if (read_mallocs > 0) {
    printf("alloc_count: urs_receive_read allocates\n");
    return 1;
  }
  return 0;
}
