/*
 * Replay recorded NMPC problem instances through the CasADi-generated RTI step and time it.
 *
 *   harness INSTANCES.bin [OUTPUTS.bin] [REPEAT]
 *
 * INSTANCES.bin (written by maglev_oc.control.codegen.write_instances):
 *   char[8]  "NMPCREC1"
 *   int32    n_instances, n_in, n_out
 *   int32    nnz_in[n_in], nnz_out[n_out]
 *   double   n_instances x (inputs of one call, concatenated: memory, y, ref)
 * Each instance is one call of nmpc_rti_step recorded in a closed-loop Python run, so the replay
 * is independent of the order of the calls and every output can be compared with Python's.
 *
 * OUTPUTS.bin (optional): the same header with the outputs (u, memory_next, diag) of every call.
 * The instances are replayed in their recorded order, REPEAT times over (default 3; the first
 * pass over all instances is not timed: page faults of the first touch), each call timed with
 * clock_gettime(CLOCK_MONOTONIC) around the single generated call. Printed: median, p99 and
 * worst over all timed calls, in microseconds, one "key: value" per line.
 *
 * The generated code (nmpc_rti_step.c/.h) comes from maglev_oc.control.codegen.generate_c.
 */
#define _POSIX_C_SOURCE 199309L
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "nmpc_rti_step.h"

static double now_us(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec * 1e6 + ts.tv_nsec * 1e-3;
}

static int cmp_double(const void* a, const void* b) {
  double x = *(const double*)a, y = *(const double*)b;
  return (x > y) - (x < y);
}

static casadi_int nnz_of(const casadi_int* sp) {
  /* CasADi's compressed sparsity: {nrow, ncol, 1} for a dense matrix, else
     {nrow, ncol, colind[ncol + 1] (colind[0] = 0), row[nnz]} */
  if (sp[2] == 1) return sp[0] * sp[1];
  return sp[2 + sp[1]];
}

static void die(const char* msg) {
  fprintf(stderr, "harness: %s\n", msg);
  exit(2);
}

int main(int argc, char** argv) {
  if (argc < 2) die("usage: harness INSTANCES.bin [OUTPUTS.bin] [REPEAT]");
  const char* out_path = argc > 2 ? argv[2] : NULL;
  int repeat = argc > 3 ? atoi(argv[3]) : 3;
  if (repeat < 2) repeat = 2;

  FILE* f = fopen(argv[1], "rb");
  if (!f) die("cannot open the instance file");
  char magic[8];
  int32_t n_inst, n_in, n_out;
  if (fread(magic, 1, 8, f) != 8 || memcmp(magic, "NMPCREC1", 8) != 0) die("not an NMPCREC1 file");
  if (fread(&n_inst, 4, 1, f) != 1 || fread(&n_in, 4, 1, f) != 1 || fread(&n_out, 4, 1, f) != 1)
    die("truncated header");
  if (n_in != nmpc_rti_step_n_in() || n_out != nmpc_rti_step_n_out())
    die("the file does not match the compiled function (number of inputs/outputs)");
  int32_t nnz_in[16], nnz_out[16];
  if (n_in > 16 || n_out > 16) die("too many inputs/outputs");
  if (fread(nnz_in, 4, n_in, f) != (size_t)n_in || fread(nnz_out, 4, n_out, f) != (size_t)n_out)
    die("truncated header");
  size_t per_in = 0, per_out = 0;
  for (int i = 0; i < n_in; ++i) {
    if (nnz_in[i] != nnz_of(nmpc_rti_step_sparsity_in(i))) die("input size differs from the compiled function");
    per_in += nnz_in[i];
  }
  for (int i = 0; i < n_out; ++i) {
    if (nnz_out[i] != nnz_of(nmpc_rti_step_sparsity_out(i))) die("output size differs from the compiled function");
    per_out += nnz_out[i];
  }
  double* inputs = malloc(sizeof(double) * per_in * (size_t)n_inst);
  double* outputs = malloc(sizeof(double) * per_out * (size_t)n_inst);
  if (!inputs || !outputs) die("out of memory");
  if (fread(inputs, sizeof(double), per_in * (size_t)n_inst, f) != per_in * (size_t)n_inst) die("truncated data");
  fclose(f);

  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  nmpc_rti_step_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real** arg = malloc(sizeof(casadi_real*) * sz_arg);
  casadi_real** res = malloc(sizeof(casadi_real*) * sz_res);
  casadi_int* iw = malloc(sizeof(casadi_int) * (sz_iw > 0 ? sz_iw : 1));
  casadi_real* w = malloc(sizeof(casadi_real) * (sz_w > 0 ? sz_w : 1));
  if (!arg || !res || !iw || !w) die("out of memory");
  nmpc_rti_step_incref();
  int mem = nmpc_rti_step_checkout();

  size_t n_times = (size_t)n_inst * (size_t)(repeat - 1);
  double* times = malloc(sizeof(double) * n_times);
  size_t t_i = 0;
  int failures = 0;
  for (int r = 0; r < repeat; ++r) {
    for (int32_t k = 0; k < n_inst; ++k) {
      const double* in = inputs + per_in * (size_t)k;
      double* out = outputs + per_out * (size_t)k;
      size_t off = 0;
      for (int i = 0; i < n_in; ++i) { arg[i] = in + off; off += nnz_in[i]; }
      off = 0;
      for (int i = 0; i < n_out; ++i) { res[i] = out + off; off += nnz_out[i]; }
      double t0 = now_us();
      int flag = nmpc_rti_step(arg, res, iw, w, mem);
      double t1 = now_us();
      if (flag && r == 0) ++failures;
      if (r > 0) times[t_i++] = t1 - t0;
    }
  }
  nmpc_rti_step_release(mem);
  nmpc_rti_step_decref();

  qsort(times, n_times, sizeof(double), cmp_double);
  double median = times[n_times / 2];
  double p99 = times[(size_t)(0.99 * (double)(n_times - 1))];
  double worst = times[n_times - 1];
  printf("instances: %d\n", n_inst);
  printf("calls_timed: %zu\n", n_times);
  printf("failed_calls: %d\n", failures);
  printf("median_us: %.3f\n", median);
  printf("p99_us: %.3f\n", p99);
  printf("worst_us: %.3f\n", worst);

  if (out_path) {
    FILE* g = fopen(out_path, "wb");
    if (!g) die("cannot write the output file");
    fwrite("NMPCREC1", 1, 8, g);
    fwrite(&n_inst, 4, 1, g);
    fwrite(&n_in, 4, 1, g);
    fwrite(&n_out, 4, 1, g);
    fwrite(nnz_in, 4, n_in, g);
    fwrite(nnz_out, 4, n_out, g);
    fwrite(outputs, sizeof(double), per_out * (size_t)n_inst, g);
    fclose(g);
  }
  free(inputs); free(outputs); free(times); free(arg); free(res); free(iw); free(w);
  return 0;
}
