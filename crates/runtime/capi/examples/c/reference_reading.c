/* Loads a calibrated device file (default: the bundled reference device) and prints, for one
 * reading, the calibrated joint angles, the tip pose and the motor torques that render one
 * wrench, with 17 significant digits (the numbers round-trip to the same doubles).
 *
 *   reference_reading [calibrated.toml] [--bench N]
 *
 * --bench N also times N calls of hapcal_evaluate (pose + body Jacobian + motor torques) on
 * one thread and prints the mean in ns. Build (from crates/runtime/capi, after
 * `cargo build --release -p hapcal-runtime-capi`):
 *
 *   cc -O2 -Iinclude examples/c/reference_reading.c ../../../target/release/libhapcal_runtime_c.a \
 *      -lpthread -ldl -lm -o reference_reading
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "hapcal_runtime.h"

#define N_JOINTS 7

static void print_row(const char *name, const double *v, size_t n) {
    printf("%s", name);
    for (size_t i = 0; i < n; i++) printf(" %.17g", v[i]);
    printf("\n");
}

int main(int argc, char **argv) {
    const char *path = "../../../fixtures/reference-device/calibrated.toml";
    long bench = 0;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--bench") == 0 && i + 1 < argc) {
            bench = strtol(argv[++i], NULL, 10);
        } else {
            path = argv[i];
        }
    }

    HapcalModel *model = NULL;
    HapcalStatus status = hapcal_model_load(path, &model);
    if (status != HAPCAL_STATUS_OK) {
        fprintf(stderr, "reference_reading: %s\n", hapcal_last_error_message());
        return 1;
    }
    size_t n = hapcal_model_n_joints(model);
    if (n != N_JOINTS) {
        fprintf(stderr, "reference_reading: expected %d joints, the model has %zu\n", N_JOINTS, n);
        hapcal_model_free(model);
        return 1;
    }

    /* One reading (rad, motor angle / R) and one wrench (N, N·m about the end point, tip frame). */
    const double theta[N_JOINTS] = {0.1, 0.5, -0.2, 1.0, 0.3, 0.6, -0.4};
    const double wrench[6] = {1.5, -2.0, 0.5, 0.05, -0.02, 0.1};
    double q[N_JOINTS], dq[N_JOINTS], tau[N_JOINTS], jac[6 * N_JOINTS];
    HapcalPose pose;

    status = hapcal_joint_angles(model, theta, n, q, dq);
    if (status == HAPCAL_STATUS_OK) {
        status = hapcal_evaluate(model, theta, n, wrench, &pose, jac, tau);
    }
    if (status != HAPCAL_STATUS_OK) {
        fprintf(stderr, "reference_reading: %s\n", hapcal_last_error_message());
        hapcal_model_free(model);
        return 1;
    }
    print_row("q_rad", q, n);
    print_row("dq_dtheta", dq, n);
    print_row("rotation", &pose.rotation[0][0], 9);
    print_row("translation_m", pose.translation_m, 3);
    print_row("body_jacobian", jac, 6 * n);
    print_row("motor_torques_nm", tau, n);

    /* A wrong joint count is an error code and a message, not a crash. */
    status = hapcal_evaluate(model, theta, n - 1, wrench, &pose, NULL, tau);
    printf("wrong_length_status %d %s\n", (int)status, hapcal_last_error_message());
    status = hapcal_evaluate(model, NULL, n, wrench, &pose, NULL, tau);
    printf("null_status %d %s\n", (int)status, hapcal_last_error_message());

    if (bench > 0) {
        double th[N_JOINTS];
        memcpy(th, theta, sizeof th);
        double sink = 0.0;
        struct timespec t0, t1;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        for (long i = 0; i < bench; i++) {
            th[0] = theta[0] + 1e-9 * (double)(i & 1023);
            hapcal_evaluate(model, th, n, wrench, &pose, jac, tau);
            sink += tau[0];
        }
        clock_gettime(CLOCK_MONOTONIC, &t1);
        double ns = (double)(t1.tv_sec - t0.tv_sec) * 1e9 + (double)(t1.tv_nsec - t0.tv_nsec);
        printf("bench_ns_per_evaluate %.1f (%ld calls, checksum %.6g)\n", ns / (double)bench, bench, sink);
    }

    hapcal_model_free(model);
    return 0;
}
