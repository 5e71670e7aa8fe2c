/* LD_PRELOAD shim for the sanitizer runs (scripts/sanitize): dlclose does nothing, so that the
 * libraries a program loads at run time (OpenMPI's components, mca_*.so) stay mapped until the
 * process ends. LeakSanitizer symbolizes its reports at exit, and an allocation made by a
 * library unloaded by then shows as "<unknown module>", which no suppression can name;
 * ThreadSanitizer stops when a library its suppressions name (called_from_lib) is unloaded. */
#include <dlfcn.h>

int dlclose(void *handle) {
  (void)handle;
  return 0;
}
