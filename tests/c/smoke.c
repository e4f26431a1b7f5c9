/*
 * A C host of libvolscatter, built by tests/tests/c_smoke.rs with
 *   cc -std=c99 -Wall -Wextra -Werror -pedantic -I plugin/include tests/c/smoke.c -o smoke \
 *      -L target/release -lvolscatter -lm -Wl,-rpath,$PWD/target/release
 * (from the repository root; docs/c-api.md gives the same line).
 * It renders scenes through the C API and dumps the numbers; the Rust test computes the same
 * scenes through the Rust API and compares. It also checks a few failures from C.
 *
 * usage: smoke SCENE.json OUT_DIR [DENSITY.vdb]
 *   A: SCENE.json loaded from the file: scattering grid, composite, reference render, and
 *      the grid written as EXR and VDB, the image as EXR.
 *   B: the same scene's lights rebuilt piecewise around a dense density buffer made here, plus
 *      a spot, a rect and a disk light.
 *   C: (with DENSITY.vdb) SCENE.json with its medium replaced by the VDB's "density" grid.
 * Exit status 0 when every call did what it should; messages on stderr otherwise.
 */
#include "volscatter.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int failures = 0;

#define CHECK(cond, ...)                                  \
  do {                                                    \
    if (!(cond)) {                                        \
      fprintf(stderr, "smoke.c:%d: ", __LINE__);          \
      fprintf(stderr, __VA_ARGS__);                       \
      fprintf(stderr, "\n");                              \
      failures++;                                         \
    }                                                     \
  } while (0)

/* Aborts the run: later steps need this one. */
#define REQUIRE_OK(call, err_fn, handle)                                                  \
  do {                                                                                    \
    VsStatus st_ = (call);                                                                \
    if (st_ != VS_STATUS_OK) {                                                            \
      fprintf(stderr, "smoke.c:%d: %s failed: %d (%s): %s\n", __LINE__, #call, (int)st_, \
              vs_status_message((int32_t)st_), err_fn(handle));                           \
      exit(2);                                                                            \
    }                                                                                     \
  } while (0)

static char *join(const char *dir, const char *name) {
  size_t n = strlen(dir) + strlen(name) + 2;
  char *p = (char *)malloc(n);
  if (!p) exit(3);
  snprintf(p, n, "%s/%s", dir, name);
  return p;
}

static void write_file(const char *dir, const char *name, const void *header, size_t header_len,
                       const float *data, size_t count) {
  char *path = join(dir, name);
  FILE *f = fopen(path, "wb");
  if (!f || fwrite(header, 1, header_len, f) != header_len ||
      fwrite(data, sizeof(float), count, f) != count || fclose(f) != 0) {
    fprintf(stderr, "cannot write %s\n", path);
    exit(3);
  }
  free(path);
}

struct progress_state {
  int calls;
  int bad;
};

static int32_t on_progress(void *user, const char *stage, float fraction) {
  struct progress_state *p = (struct progress_state *)user;
  p->calls++;
  if (stage == NULL || stage[0] == '\0' || !(fraction >= 0.0f && fraction <= 1.0f)) p->bad++;
  return 1;
}

/* Solves, checks the result's shape, dumps "dims[3] u32, matrix[16] f32, rgb floats". */
static VsResult *solve_and_dump(VsScene *scene, const char *dir, const char *name) {
  struct progress_state progress = {0, 0};
  VsResult *result = NULL;
  uint32_t dims[3];
  float matrix[16];
  size_t count = 0;
  float *rgb;
  unsigned char header[3 * 4 + 16 * 4];

  REQUIRE_OK(vs_scene_solve(scene, on_progress, &progress, &result), vs_scene_last_error, scene);
  CHECK(result != NULL, "solve gave no result");
  CHECK(progress.calls > 0 && progress.bad == 0, "%s: progress called %d times, %d bad", name,
        progress.calls, progress.bad);
  REQUIRE_OK(vs_result_dims(result, dims), vs_result_last_error, result);
  REQUIRE_OK(vs_result_float_count(result, &count), vs_result_last_error, result);
  CHECK(count == (size_t)dims[0] * dims[1] * dims[2] * 3, "float count %zu vs dims", count);
  REQUIRE_OK(vs_result_index_to_world(result, matrix), vs_result_last_error, result);
  CHECK(matrix[12] == 0.0f && matrix[13] == 0.0f && matrix[14] == 0.0f && matrix[15] == 1.0f,
        "last row of index_to_world is not 0 0 0 1");
  rgb = (float *)malloc(count * sizeof(float));
  if (!rgb) exit(3);
  /* A buffer one float short is refused, and the message says why. */
  CHECK(vs_result_copy_rgb(result, rgb, count - 1) == VS_STATUS_BUFFER_SIZE, "short buffer accepted");
  CHECK(strstr(vs_result_last_error(result), "needs exactly") != NULL, "message: %s",
        vs_result_last_error(result));
  REQUIRE_OK(vs_result_copy_rgb(result, rgb, count), vs_result_last_error, result);
  CHECK(vs_result_last_error(result)[0] == '\0', "error not cleared after success");
  memcpy(header, dims, sizeof dims);
  memcpy(header + sizeof dims, matrix, sizeof matrix);
  write_file(dir, name, header, sizeof header, rgb, count);
  free(rgb);
  return result;
}

/* Dumps "width, height u32, rgba floats" of an image and destroys it. */
static void dump_image(VsImage *image, const char *dir, const char *name) {
  uint32_t wh[2];
  size_t count;
  float *rgba;
  REQUIRE_OK(vs_image_size(image, &wh[0], &wh[1]), vs_image_last_error, image);
  count = (size_t)wh[0] * wh[1] * 4;
  rgba = (float *)malloc(count * sizeof(float));
  if (!rgba) exit(3);
  REQUIRE_OK(vs_image_copy_rgba(image, rgba, count), vs_image_last_error, image);
  write_file(dir, name, wh, sizeof wh, rgba, count);
  free(rgba);
  CHECK(vs_image_destroy(image) == VS_STATUS_OK, "image destroy");
}

static VsImage *render(VsScene *scene) {
  VsImage *image = NULL;
  REQUIRE_OK(vs_scene_render_reference(scene, NULL, NULL, &image), vs_scene_last_error, scene);
  return image;
}

int main(int argc, char **argv) {
  const char *scene_path, *dir;
  VsScene *a = NULL, *b = NULL;
  VsResult *result;
  VsImage *image = NULL;
  char *path;

  if (argc < 3) {
    fprintf(stderr, "usage: smoke SCENE.json OUT_DIR [DENSITY.vdb]\n");
    return 64;
  }
  scene_path = argv[1];
  dir = argv[2];

  if (vs_abi_version() != VS_ABI_VERSION) {
    fprintf(stderr, "ABI mismatch: library %u, header %u\n", vs_abi_version(), VS_ABI_VERSION);
    return 1;
  }
  printf("libvolscatter %s, ABI %u\n", vs_version(), vs_abi_version());

  /* ---- the solver registry: the JSON hosts build their menus from ------------------- */
  {
    const char *solvers = NULL;
    if (vs_solvers_json(&solvers) != VS_STATUS_OK || solvers == NULL || strstr(solvers, "\"name\":\"pop\"") == NULL) {
      fprintf(stderr, "vs_solvers_json failed or does not list pop\n");
      return 1;
    }
    printf("solvers: %lu bytes of JSON\n", (unsigned long)strlen(solvers));
  }

  /* ---- A: scene file ---------------------------------------------------------------- */
  REQUIRE_OK(vs_scene_new(&a), vs_scene_last_error, a);
  REQUIRE_OK(vs_scene_load_file(a, scene_path), vs_scene_last_error, a);
  result = solve_and_dump(a, dir, "grid_a.bin");
  path = join(dir, "grid_a.exr");
  REQUIRE_OK(vs_result_write_grid(result, path, VS_GRID_FORMAT_EXR), vs_result_last_error, result);
  free(path);
  path = join(dir, "grid_a.vdb");
  REQUIRE_OK(vs_result_write_grid(result, path, VS_GRID_FORMAT_VDB), vs_result_last_error, result);
  free(path);
  CHECK(vs_result_write_grid(result, "x.bin", 7) == VS_STATUS_INVALID_ARGUMENT, "format 7 accepted");
  REQUIRE_OK(vs_result_composite(result, 0, 0, 0.0f, &image), vs_result_last_error, result);
  path = join(dir, "composite_a.exr");
  REQUIRE_OK(vs_image_write_exr(image, path), vs_image_last_error, image);
  free(path);
  dump_image(image, dir, "composite_a.bin");
  CHECK(vs_result_destroy(result) == VS_STATUS_OK, "result destroy");
  CHECK(vs_result_destroy(result) == VS_STATUS_INVALID_HANDLE, "double destroy not detected");
  image = render(a);
  {
    uint32_t w, h;
    size_t n;
    float *single;
    REQUIRE_OK(vs_image_size(image, &w, &h), vs_image_last_error, image);
    n = (size_t)w * h * 3;
    single = (float *)malloc(n * sizeof(float));
    if (!single) exit(3);
    REQUIRE_OK(vs_image_copy_aov(image, "single", single, n), vs_image_last_error, image);
    CHECK(vs_image_copy_aov(image, "nope", single, n) == VS_STATUS_INVALID_ARGUMENT, "unknown AOV");
    CHECK(strstr(vs_image_last_error(image), "single") != NULL, "AOV message lists layers: %s",
          vs_image_last_error(image));
    free(single);
  }
  dump_image(image, dir, "render_a.bin");

  /* Failures from C: a status and a message, never a crash. */
  CHECK(vs_scene_load_json(NULL, "{}", NULL) == VS_STATUS_NULL_ARGUMENT, "NULL scene");
  CHECK(vs_scene_load_json(a, "{\"format\": 1}", NULL) == VS_STATUS_INVALID_SCENE, "bad JSON");
  CHECK(strstr(vs_scene_last_error(a), "medium") != NULL, "message names the field: %s",
        vs_scene_last_error(a));
  {
    float nan_dir[3] = {0.0f, 0.0f, 0.0f};
    float e[3] = {1.0f, 1.0f, 1.0f};
    nan_dir[1] = (float)NAN;
    CHECK(vs_scene_add_distant_light(a, nan_dir, e, 0.0f) == VS_STATUS_INVALID_ARGUMENT, "NaN");
    CHECK(strstr(vs_scene_last_error(a), "direction") != NULL, "NaN message: %s", vs_scene_last_error(a));
  }

  /* ---- B: piecewise, dense buffer from the host ------------------------------------- */
  {
    enum { NX = 20, NY = 16, NZ = 12 };
    static float density[NX * NY * NZ];
    const float voxel = 0.1f;
    /* Row-major index-to-world: 0.1 m voxels, centred on the origin. */
    const float i2w[16] = {voxel, 0, 0, -0.5f * voxel * (NX - 1),
                           0, voxel, 0, -0.5f * voxel * (NY - 1),
                           0, 0, voxel, -0.5f * voxel * (NZ - 1),
                           0, 0, 0, 1};
    const float ds[3] = {8.0f, 8.0f, 8.0f}, albedo[3] = {0.9f, 0.85f, 0.8f};
    const float sun_dir[3] = {-0.3f, 0.5f, -0.8f}, sun_e[3] = {4.0f, 3.8f, 3.5f};
    const float lamp_pos[3] = {1.5f, -1.0f, 1.0f}, lamp_i[3] = {2.0f, 1.5f, 1.0f};
    const float sky[3] = {0.1f, 0.15f, 0.25f};
    const float spot_pos[3] = {-1.5f, -1.0f, 1.2f}, spot_dir[3] = {1.5f, 1.0f, -1.2f}, spot_i[3] = {3.0f, 2.5f, 2.0f};
    const float rect_pos[3] = {0.0f, 0.0f, 1.5f}, down[3] = {0.0f, 0.0f, -1.0f}, rect_t[3] = {1.0f, 1.0f, 0.0f};
    const float rect_l[3] = {0.8f, 0.8f, 1.0f};
    const float disk_pos[3] = {0.0f, -1.5f, 0.0f}, disk_n[3] = {0.0f, 1.0f, 0.0f}, disk_l[3] = {1.0f, 0.7f, 0.5f};
    const float cam[3] = {0.3f, -4.0f, 0.5f}, target[3] = {0.0f, 0.0f, 0.0f};
    size_t lights = 0;
    unsigned dims_header[3] = {NX, NY, NZ};
    int i, j, k;
    for (k = 0; k < NZ; k++)
      for (j = 0; j < NY; j++)
        for (i = 0; i < NX; i++) {
          float x = (i - 0.5f * (NX - 1)) / (0.5f * NX), y = (j - 0.5f * (NY - 1)) / (0.5f * NY),
                z = (k - 0.5f * (NZ - 1)) / (0.5f * NZ);
          float r2 = x * x + y * y + z * z;
          density[(k * NY + j) * NX + i] = r2 < 1.0f ? 1.0f - r2 : 0.0f;
        }
    write_file(dir, "dense.bin", dims_header, sizeof dims_header, density, NX * NY * NZ);

    REQUIRE_OK(vs_scene_new(&b), vs_scene_last_error, b);
    CHECK(vs_scene_solve(b, NULL, NULL, &result) == VS_STATUS_INVALID_SCENE && result == NULL,
          "an empty scene solved");
    CHECK(vs_scene_set_medium_dense(b, density, NX * NY * NZ - 1, NX, NY, NZ, i2w) == VS_STATUS_BUFFER_SIZE,
          "mismatched length accepted");
    REQUIRE_OK(vs_scene_set_medium_dense(b, density, NX * NY * NZ, NX, NY, NZ, i2w), vs_scene_last_error, b);
    REQUIRE_OK(vs_scene_set_material(b, ds, albedo, 0.3f), vs_scene_last_error, b);
    REQUIRE_OK(vs_scene_add_distant_light(b, sun_dir, sun_e, 0.0f), vs_scene_last_error, b);
    REQUIRE_OK(vs_scene_add_point_light(b, lamp_pos, lamp_i, 0.0f), vs_scene_last_error, b);
    REQUIRE_OK(vs_scene_add_dome_light(b, sky), vs_scene_last_error, b);
    REQUIRE_OK(vs_scene_add_spot_light(b, spot_pos, spot_dir, spot_i, 25.0f, 0.3f, 0.0f), vs_scene_last_error, b);
    REQUIRE_OK(vs_scene_add_rect_light(b, rect_pos, down, rect_t, 0.6f, 0.4f, rect_l), vs_scene_last_error, b);
    REQUIRE_OK(vs_scene_add_disk_light(b, disk_pos, disk_n, 0.3f, disk_l), vs_scene_last_error, b);
    CHECK(vs_scene_add_disk_light(b, disk_pos, disk_n, 0.0f, disk_l) == VS_STATUS_INVALID_SCENE, "disk of radius 0");
    CHECK(strstr(vs_scene_last_error(b), "radius") != NULL, "disk message: %s", vs_scene_last_error(b));
    REQUIRE_OK(vs_scene_light_count(b, &lights), vs_scene_last_error, b);
    CHECK(lights == 6, "light count %zu", lights);
    REQUIRE_OK(vs_scene_set_camera(b, cam, target, NULL, 45.0f, 24, 16), vs_scene_last_error, b);
    REQUIRE_OK(vs_scene_set_solver(b, "reference", "{\"seed\": 3, \"spp\": 4, \"grid_resolution\": 10, \"grid_spp\": 8}"),
               vs_scene_last_error, b);
    result = solve_and_dump(b, dir, "grid_b.bin");
    CHECK(vs_result_destroy(result) == VS_STATUS_OK, "result destroy");
    dump_image(render(b), dir, "render_b.bin");
  }

  /* ---- C: VDB medium ---------------------------------------------------------------- */
  if (argc > 3) {
    REQUIRE_OK(vs_scene_set_medium_vdb(a, argv[3], "density", NULL), vs_scene_last_error, a);
    CHECK(vs_scene_set_medium_vdb(a, argv[3], "no_such_grid", NULL) != VS_STATUS_OK, "missing grid");
    result = solve_and_dump(a, dir, "grid_c.bin");
    CHECK(vs_result_destroy(result) == VS_STATUS_OK, "result destroy");
  }

  CHECK(vs_scene_destroy(a) == VS_STATUS_OK, "destroy a");
  CHECK(vs_scene_destroy(b) == VS_STATUS_OK, "destroy b");
  CHECK(vs_scene_load_default(a) == VS_STATUS_INVALID_HANDLE, "destroyed handle used");
  CHECK(strcmp(vs_scene_last_error(a), vs_status_message(VS_STATUS_INVALID_HANDLE)) == 0,
        "message for a destroyed handle");

  if (failures) {
    fprintf(stderr, "smoke: %d check(s) failed\n", failures);
    return 1;
  }
  printf("smoke: ok\n");
  return 0;
}
