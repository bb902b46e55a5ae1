/* ur_rtde's CMake build generates this header (GenerateExportHeader); the sdist does not ship
 * it. hrc-adapt links the library the wheel built, so the macros only need to name symbols
 * with default visibility. */
#ifndef RTDE_EXPORT_H
#define RTDE_EXPORT_H
#define RTDE_EXPORT __attribute__((visibility("default")))
#define RTDE_NO_EXPORT __attribute__((visibility("hidden")))
#define RTDE_DEPRECATED __attribute__((__deprecated__))
#endif
