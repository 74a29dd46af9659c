/* A firmware that crashes at once with a known stack (crash_here <- caller <- main), for the
   crash report's first frames (FirmwareSupervision.ACrashWithACoreIsReportedWithItsFirstFrames).
   Built with -g -O0 and without sanitizers: the kernel, not ASan, must see the SIGSEGV. */
#include <stddef.h>

static volatile int* target = NULL;

__attribute__((noinline)) void crash_here(volatile int* p) { *p = 1; }
__attribute__((noinline)) void caller(void) { crash_here(target); }

int main(void) {
  caller();
  return 0;
}
