/* LD_PRELOAD shim for the sanitizer runs (scripts/sanitize): dlclose does nothing, so that the
 * libraries a program loads at run time (OpenMPI's components, mca_*.so) stay mapped until the
 * process ends. LeakSanitizer symbolizes its reports at exit; an allocation made by a library
 * that was unloaded by then shows as "<unknown module>" and no suppression can name it. Nothing
 * else changes: a library's memory is never given back before exit anyway in these runs. */
#include <dlfcn.h>

int dlclose(void *handle) {
  (void)handle;
  return 0;
}
