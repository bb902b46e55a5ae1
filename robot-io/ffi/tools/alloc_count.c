/* Counts the malloc calls of one urs_receive_read (ur_rtde's getters) on the reading thread.
 * Not part of the build: an executable's own malloc interposes on librtde's and libstdc++'s,
 * which the Rust counting allocator cannot see. Build and run (scripts/deps/env.sh sourced,
 * an emulator on 127.0.0.7: `hrc-adapt emulate --sim --bind 127.0.0.7`):
 *
 *   g++ -std=c++17 -D_GLIBCXX_USE_CXX11_ABI=0 -c robot-io/ffi/ur_rtde_shim.cpp \
 *       -Irobot-io/ffi/include -I"$UR_RTDE_INCLUDE" -o /tmp/shim.o
 *   gcc -c robot-io/ffi/tools/alloc_count.c -Irobot-io/ffi -o /tmp/count.o
 *   g++ /tmp/count.o /tmp/shim.o -L"$UR_RTDE_LIB_DIR" -lrtde -Wl,-rpath,"$UR_RTDE_LIB_DIR" -o /tmp/count
 *   /tmp/count
 */
#define _GNU_SOURCE
#include "ur_rtde_shim.h"
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>
extern void *__libc_malloc(size_t);
static __thread int counting = 0; static __thread long count = 0;
void *malloc(size_t n){ if(counting) count++; return __libc_malloc(n); }
int main(){char e[256]; urs_receive*h=urs_receive_new("127.0.0.7",500,e,256); if(!h){printf("%s\n",e);return 1;}
 urs_state s; usleep(200000); for(int i=0;i<10;i++) urs_receive_read(h,&s);
 counting=1; long n=1000; for(int i=0;i<n;i++){ urs_receive_read(h,&s); usleep(2000);} counting=0;
 printf("malloc calls on the reading thread: %ld over %ld urs_receive_read (%.2f per read), ts %.3f\n",count,n,(double)count/n,s.timestamp_s);
 urs_receive_free(h); return 0;}
