/* Loads a calibrated URDF robot (default: the C ABI's test robot, a 7-joint arm with link
 * masses and joint compliances in its sidecar) with the tips ball_link and tool0, and prints,
 * at one joint configuration, the rigid tip pose, the spatial and body Jacobians, the gravity
 * torques, the tips' poses deflected under the robot's own weight (the calibrated model's
 * prediction), the region flag, and the command that brings the deflected tip onto the rigid
 * tip's pose (compensation), with 17 significant digits (the numbers round-trip to the same
 * doubles).
 *
 *   robot [robot.urdf] [--bench N]
 *
 * --bench N also times N cycles of tip pose + spatial Jacobian + deflected tip poses on one
 * thread and prints the mean in ns. Build (from crates/runtime/capi, after
 * `cargo build --release -p hapcal-runtime-capi`):
 *
 *   cc -std=c99 -D_POSIX_C_SOURCE=199309L -O2 -Iinclude examples/c/robot.c \
 *      ../../../target/release/libhapcal_runtime_c.a -lpthread -ldl -lm -o robot
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "hapcal_runtime.h"

#define N_JOINTS 7
#define N_TIPS 2

static void print_row(const char *name, const double *v, size_t n) {
    printf("%s", name);
    for (size_t i = 0; i < n; i++) printf(" %.17g", v[i]);
    printf("\n");
}

static void print_pose(const char *name, const HapcalPose *pose) {
    char key[64];
    snprintf(key, sizeof key, "%s_rotation", name);
    print_row(key, &pose->rotation[0][0], 9);
    snprintf(key, sizeof key, "%s_translation_m", name);
    print_row(key, pose->translation_m, 3);
}

static int fail(HapcalRobot *robot) {
    fprintf(stderr, "robot: %s\n", hapcal_last_error_message());
    hapcal_robot_free(robot);
    return 1;
}

int main(int argc, char **argv) {
    const char *path = "tests/data/iiwa14_calibrated.urdf";
    long bench = 0;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--bench") == 0 && i + 1 < argc) {
            bench = strtol(argv[++i], NULL, 10);
        } else {
            path = argv[i];
        }
    }

    const char *tips[N_TIPS] = {"ball_link", "tool0"};
    HapcalRobot *robot = NULL;
    if (hapcal_robot_load(path, tips, N_TIPS, &robot) != HAPCAL_STATUS_OK) return fail(robot);
    size_t n = hapcal_robot_n_joints(robot);
    if (n != N_JOINTS || hapcal_robot_n_tips(robot) != N_TIPS) {
        fprintf(stderr, "robot: expected %d joints and %d tips, the robot has %zu and %zu\n",
                N_JOINTS, N_TIPS, n, hapcal_robot_n_tips(robot));
        hapcal_robot_free(robot);
        return 1;
    }

    /* Names, into a caller's buffer. */
    char name[64];
    printf("joint_names");
    for (size_t j = 0; j < n; j++) {
        if (hapcal_robot_joint_name(robot, j, name, sizeof name, NULL) != HAPCAL_STATUS_OK) return fail(robot);
        printf(" %s", name);
    }
    printf("\ntip_names");
    for (size_t t = 0; t < N_TIPS; t++) {
        if (hapcal_robot_tip_name(robot, t, name, sizeof name, NULL) != HAPCAL_STATUS_OK) return fail(robot);
        printf(" %s", name);
    }
    printf("\nhas_link_masses %d\n", (int)hapcal_robot_has_link_masses(robot));

    /* One configuration, rad. */
    const double q[N_JOINTS] = {0.3, 0.7, -0.2, -1.2, 0.4, 0.9, 0.1};
    HapcalPose pose, jac_pose, deflected[N_TIPS];
    HapcalDeflection deflection;
    double spatial[6 * N_JOINTS], body[6 * N_JOINTS], tau[N_JOINTS];
    if (hapcal_robot_tip_pose(robot, 0, q, n, &pose) != HAPCAL_STATUS_OK ||
        hapcal_robot_spatial_jacobian(robot, 0, q, n, spatial, &jac_pose) != HAPCAL_STATUS_OK ||
        hapcal_robot_body_jacobian(robot, 0, q, n, body, NULL) != HAPCAL_STATUS_OK ||
        hapcal_robot_gravity_torques(robot, q, n, tau) != HAPCAL_STATUS_OK ||
        hapcal_robot_deflected_tip_poses(robot, q, n, deflected, N_TIPS, &deflection) != HAPCAL_STATUS_OK) {
        return fail(robot);
    }
    print_pose("tip_pose", &pose);
    print_row("spatial_jacobian", spatial, 6 * n);
    print_row("body_jacobian", body, 6 * n);
    print_row("gravity_torques_nm", tau, n);
    print_pose("deflected0", &deflected[0]);
    print_pose("deflected1", &deflected[1]);
    printf("deflection %zu %.17g %d\n", deflection.iterations, deflection.final_step_rad,
           (int)deflection.converged);

    /* The region the calibration was fitted on. */
    size_t joint;
    double distance;
    if (hapcal_robot_outside_region(robot, q, n, &joint, &distance) != HAPCAL_STATUS_OK) return fail(robot);
    if (joint == HAPCAL_INSIDE_REGION) {
        printf("region inside\n");
    } else {
        printf("region outside %zu %.17g\n", joint, distance);
    }

    /* Compensation: the command at which the deflected tip 0 takes the pose the rigid robot
     * has at q (the nominal solution), from q. */
    HapcalTarget target = {HAPCAL_TARGET_POSE, pose};
    HapcalCompensationConfig config = {1e-9, 1e-9, 50, 1e-3, 0.1};
    double command[N_JOINTS];
    HapcalCompensation result;
    if (hapcal_robot_compensate(robot, 0, &target, q, n, &config, command, &result) != HAPCAL_STATUS_OK) {
        return fail(robot);
    }
    print_row("command_rad", command, n);
    printf("compensation %d %zu %.17g %.17g %zu\n", (int)result.reached, result.iterations,
           result.position_error_m, result.orientation_error_rad, result.deflection.iterations);

    /* Failures are status codes and messages, not crashes. */
    double bad[N_JOINTS];
    memcpy(bad, q, sizeof bad);
    bad[3] = NAN;
    HapcalStatus status = hapcal_robot_tip_pose(robot, 0, bad, n, &pose);
    printf("nan_status %d %s\n", (int)status, hapcal_last_error_message());
    status = hapcal_robot_deflected_tip_poses(robot, q, n - 1, deflected, N_TIPS, NULL);
    printf("wrong_length_status %d %s\n", (int)status, hapcal_last_error_message());
    status = hapcal_robot_spatial_jacobian(robot, N_TIPS, q, n, spatial, NULL);
    printf("bad_tip_status %d %s\n", (int)status, hapcal_last_error_message());
    char small[4];
    size_t length = 0;
    status = hapcal_robot_joint_name(robot, 0, small, sizeof small, &length);
    printf("small_buffer_status %d %zu %s\n", (int)status, length, hapcal_last_error_message());

    if (bench > 0) {
        double qb[N_JOINTS];
        memcpy(qb, q, sizeof qb);
        double sink = 0.0;
        struct timespec t0, t1;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        for (long i = 0; i < bench; i++) {
            qb[0] = q[0] + 1e-9 * (double)(i & 1023);
            hapcal_robot_tip_pose(robot, 0, qb, n, &pose);
            hapcal_robot_spatial_jacobian(robot, 0, qb, n, spatial, NULL);
            hapcal_robot_deflected_tip_poses(robot, qb, n, deflected, N_TIPS, NULL);
            sink += deflected[0].translation_m[0] + spatial[0];
        }
        clock_gettime(CLOCK_MONOTONIC, &t1);
        double ns = (double)(t1.tv_sec - t0.tv_sec) * 1e9 + (double)(t1.tv_nsec - t0.tv_nsec);
        printf("bench_ns_per_cycle %.1f (%ld cycles, checksum %.6g)\n", ns / (double)bench, bench, sink);
    }

    hapcal_robot_free(robot);
    return 0;
}
