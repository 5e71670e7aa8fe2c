// LD_PRELOAD shim for the full-disk test (tests/miniapps/full_disk_test.sh): the step GLBs whose
// numbers LDIMESH_TEST_FULL_DISK lists (comma-separated, counting from 1 the GLBs the process
// starts writing) fail as on a full disk: half of the bytes reach the file, then fwrite stops
// short with errno ENOSPC, as the kernel's write does when the disk fills mid-file. Writes to
// any other file are left alone (a step's GLB is written through a hidden temporary file,
// ".step_N.glb.tmp.…", by one fwrite: transport/delivery/src/snapshot_store.cpp).
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

// Whether GLB number `k` is one the environment says fails.
static int fails(long k) {
  const char* list = getenv("LDIMESH_TEST_FULL_DISK");
  while (list && *list) {
    char* end;
    const long n = strtol(list, &end, 10);
    if (end == list) return 0;
    if (n == k) return 1;
    list = *end == ',' ? end + 1 : end;
  }
  return 0;
}

// Whether `file` is the temporary file of a step's GLB.
static int step_glb(FILE* file) {
  char link[64], path[PATH_MAX];
  snprintf(link, sizeof link, "/proc/self/fd/%d", fileno(file));
  const ssize_t n = readlink(link, path, sizeof path - 1);
  if (n <= 0) return 0;
  path[n] = '\0';
  const char* base = strrchr(path, '/');
  base = base ? base + 1 : path;
  return strncmp(base, ".step_", 6) == 0 && strstr(base, ".glb.tmp.") != NULL;
}

size_t fwrite(const void* data, size_t size, size_t count, FILE* file) {
  static size_t (*real)(const void*, size_t, size_t, FILE*);
  static long glbs;
  if (!real) real = (size_t(*)(const void*, size_t, size_t, FILE*))dlsym(RTLD_NEXT, "fwrite");
  if (!step_glb(file) || !fails(__atomic_add_fetch(&glbs, 1, __ATOMIC_SEQ_CST)))
    return real(data, size, count, file);
  const size_t half = real(data, size, count / 2, file);
  errno = ENOSPC;
  return half;
}
