// LD_PRELOAD shim for the kill test (tests/miniapps/kill_test.sh): fwrite of more than 4 KiB
// goes to the file in 4 KiB pieces, each flushed and followed by a 20 ms pause, so that a job
// killed at a random moment is often in the middle of writing a step file (a step's GLB then
// takes tens of milliseconds to write instead of microseconds). Nothing else changes.
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <time.h>

size_t fwrite(const void* data, size_t size, size_t count, FILE* file) {
  static size_t (*real)(const void*, size_t, size_t, FILE*);
  if (!real) real = (size_t(*)(const void*, size_t, size_t, FILE*))dlsym(RTLD_NEXT, "fwrite");
  enum { kPiece = 4096 };
  if (size != 1 || count <= kPiece) return real(data, size, count, file);
  const struct timespec pause = {0, 20000000};
  size_t done = 0;
  while (done < count) {
    const size_t piece = count - done < kPiece ? count - done : kPiece;
    const size_t written = real((const char*)data + done, 1, piece, file);
    done += written;
    if (written < piece || fflush(file) != 0) break;
    nanosleep(&pause, NULL);
  }
  return done;
}
