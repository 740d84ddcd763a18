/* A minimal FMI 2.0 co-simulation master in C (tests/test_fmu.py): loads a unit's binary with dlopen
 * and closes a P loop u = kp (ref - y) around one input and one output, steps of h, then prints y.
 *   fmi2_master BINARY.so GUID RESOURCES_URI VR_IN VR_OUT STEPS H KP REF
 * Exit 1 with a line on stdout when the binary, an instance or a step fails. */
#include <dlfcn.h>
#include <unistd.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

typedef void *(*instantiate_t)(const char *, int, const char *, const char *, const void *, int, int);
typedef int (*setup_t)(void *, int, double, double, int, double);
typedef int (*mode_t_)(void *);
typedef int (*step_t)(void *, double, double, int);
typedef int (*real_t)(void *, const unsigned *, size_t, double *);

static void logger(void *env, const char *inst, int status, const char *cat, const char *msg, ...) {
  va_list ap;
  (void)env; (void)inst;
  va_start(ap, msg);
  printf("log [%s %d] ", cat, status);
  vprintf(msg, ap);
  printf("\n");
  va_end(ap);
}

static void *sym(void *lib, const char *name) {
  void *f = dlsym(lib, name);
  if (!f) { printf("no symbol %s\n", name); exit(1); }
  return f;
}

int main(int argc, char **argv) {
  if (argc != 10) { printf("usage: fmi2_master BINARY GUID RESOURCES VR_IN VR_OUT STEPS H KP REF\n"); return 1; }
  void *lib = dlopen(argv[1], RTLD_NOW);
  if (!lib) { printf("dlopen: %s\n", dlerror()); return 1; }
  void *callbacks[5] = {(void *)logger, (void *)calloc, (void *)free, NULL, NULL};
  unsigned vin = (unsigned)atoi(argv[4]), vout = (unsigned)atoi(argv[5]);
  int steps = atoi(argv[6]);
  double h = atof(argv[7]), kp = atof(argv[8]), ref = atof(argv[9]), y = 0.0, u;
  void *c = ((instantiate_t)sym(lib, "fmi2Instantiate"))("plant", 1, argv[2], argv[3], callbacks, 0, 0);
  if (!c) { printf("fmi2Instantiate failed\n"); return 1; }
  ((setup_t)sym(lib, "fmi2SetupExperiment"))(c, 0, 0.0, 0.0, 1, steps * h);
  ((mode_t_)sym(lib, "fmi2EnterInitializationMode"))(c);
  ((mode_t_)sym(lib, "fmi2ExitInitializationMode"))(c);
  real_t get = (real_t)sym(lib, "fmi2GetReal"), set = (real_t)sym(lib, "fmi2SetReal");
  step_t step = (step_t)sym(lib, "fmi2DoStep");
  for (int k = 0; k < steps; k++) {
    get(c, &vout, 1, &y);
    u = kp * (ref - y);
    set(c, &vin, 1, &u);
    int status = step(c, k * h, h, 1);
    if (status) { printf("fmi2DoStep status %d at step %d\n", status, k); return 1; }
  }
  get(c, &vout, 1, &y);
  printf("y %.17g\n", y);
  fflush(stdout);
  /* the end of a co-simulation as FMI 2.0 orders it */
  ((mode_t_)sym(lib, "fmi2Terminate"))(c);
  ((void (*)(void *))sym(lib, "fmi2FreeInstance"))(c);
  /* PythonFMU 0.7's binary finalizes its interpreter in a library destructor that runs after the
     process's exit handlers have freed the interpreter's holder (valgrind: an invalid read in
     finalizePythonInterpreter of a block freed by __run_exit_handlers): a normal exit can abort
     with heap corruption after the results are complete.  End the process without exit handlers. */
  _exit(0);
}
