/* Loads a calibrated URDF robot (default: the C ABI's test robot, a 7-joint arm with link
 * masses and joint compliances in its sidecar) with the tips ball_link and tool0, and prints,
 * at one joint configuration, the rigid tip pose, the spatial and body Jacobians, the gravity
 * torques, the tips' poses deflected under the robot's own weight (the calibrated model's
 * prediction), the joint limits and compliances, the deflected joint angles, the deflected
 * pose and spatial Jacobian of one control cycle, the identified instrument and marker
 * frames, the poses of the robot with its marker on tip 0, the predictions with their 1σ in
 * the instrument frame, the region flag, and the command that brings the deflected tip onto
 * the rigid tip's pose (compensation), with 17 significant digits (the numbers round-trip to
 * the same doubles).
 *
 *   robot [robot.urdf] [--record record.urdf] [--bench N]
 *
 * --record also loads a robot whose sidecar is a calibration record (with tip ball_link) and
 * prints its prediction with 1σ and the region flag at a reading past its training range.
 *
 * --bench N also times N cycles of tip pose + spatial Jacobian + deflected tip poses on one
 * thread, and N calls of the deflected pose + spatial Jacobian, and prints the means in ns. Build (from crates/runtime/capi, after
 * `cargo build --release -p hapcal-runtime-capi`):
 *
 *   cc -std=c99 -D_POSIX_C_SOURCE=199309L -O2 -Iinclude examples/c/robot.c \
 *      ../../../target/release/libhapcal_runtime_c.a -lpthread -ldl -lm -o robot
 */
#include <math.h>
#include <stdbool.h>
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
    const char *record_path = NULL;
    long bench = 0;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--bench") == 0 && i + 1 < argc) {
            bench = strtol(argv[++i], NULL, 10);
        } else if (strcmp(argv[i], "--record") == 0 && i + 1 < argc) {
            record_path = argv[++i];
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

    /* Limits and compliances. */
    double lower[N_JOINTS], upper[N_JOINTS], k[N_JOINTS];
    if (hapcal_robot_limits(robot, lower, upper, n) != HAPCAL_STATUS_OK ||
        hapcal_robot_compliances(robot, k, n) != HAPCAL_STATUS_OK) {
        return fail(robot);
    }
    print_row("limits_lower", lower, n);
    print_row("limits_upper", upper, n);
    print_row("compliances", k, n);
    printf("is_prismatic %d\n", (int)hapcal_robot_is_prismatic(robot, 0));

    /* The deflected joint angles, and one control cycle's deflected pose and spatial
     * Jacobian (at the deflected angles) from one deflection. */
    double theta[N_JOINTS], deflected_jac[6 * N_JOINTS];
    HapcalPose deflected_pose;
    HapcalDeflection theta_deflection, jac_deflection;
    if (hapcal_robot_deflect(robot, q, n, theta, &theta_deflection) != HAPCAL_STATUS_OK ||
        hapcal_robot_deflected_spatial_jacobian(robot, 0, q, n, deflected_jac, &deflected_pose,
                                                &jac_deflection) != HAPCAL_STATUS_OK) {
        return fail(robot);
    }
    print_row("deflected_theta_rad", theta, n);
    printf("theta_deflection %zu %.17g %d\n", theta_deflection.iterations,
           theta_deflection.final_step_rad, (int)theta_deflection.converged);
    print_pose("deflected_jacobian_pose", &deflected_pose);
    print_row("deflected_spatial_jacobian", deflected_jac, 6 * n);
    printf("jacobian_deflection %zu\n", jac_deflection.iterations);

    /* The calibration's identified frames, and the robot with marker1 on tip 0. */
    HapcalPose instrument, marker, unused;
    bool found_instrument = false, found_marker = false, found_other = true;
    if (hapcal_robot_frame(robot, "instrument", &instrument, &found_instrument) != HAPCAL_STATUS_OK ||
        hapcal_robot_frame(robot, "marker1", &marker, &found_marker) != HAPCAL_STATUS_OK ||
        hapcal_robot_frame(robot, "marker9", &unused, &found_other) != HAPCAL_STATUS_OK) {
        return fail(robot);
    }
    printf("frames_found %d %d %d\n", (int)found_instrument, (int)found_marker, (int)found_other);
    print_pose("frame_instrument", &instrument);
    print_pose("frame_marker1", &marker);
    HapcalRobot *marked = NULL;
    if (hapcal_robot_with_marker(robot, 0, &marker, &marked) != HAPCAL_STATUS_OK) return fail(robot);
    HapcalPose marked_pose, marked_deflected[N_TIPS];
    HapcalStatus marked_status = hapcal_robot_tip_pose(marked, 0, q, n, &marked_pose);
    if (marked_status == HAPCAL_STATUS_OK) {
        marked_status = hapcal_robot_deflected_tip_poses(marked, q, n, marked_deflected, N_TIPS, NULL);
    }
    hapcal_robot_free(marked);
    if (marked_status != HAPCAL_STATUS_OK) return fail(robot);
    print_pose("marked_tip_pose", &marked_pose);
    print_pose("marked_deflected0", &marked_deflected[0]);

    /* Predictions with their 1σ, in the instrument frame (marker1 on tip 0). */
    HapcalPredictor *predictor = NULL;
    if (hapcal_predictor_new(robot, HAPCAL_FRAME_INSTRUMENT, &predictor) != HAPCAL_STATUS_OK) return fail(robot);
    HapcalTipPrediction predicted[N_TIPS];
    char note[256];
    HapcalStatus predicted_status = hapcal_predictor_predict(predictor, q, n, predicted, N_TIPS);
    if (predicted_status == HAPCAL_STATUS_OK) {
        predicted_status = hapcal_predictor_uncertainty_note(predictor, note, sizeof note, NULL);
    }
    printf("predictor %d %d %zu\n", (int)hapcal_predictor_basis(predictor),
           (int)hapcal_predictor_has_uncertainty(predictor), hapcal_predictor_n_values(predictor));
    hapcal_predictor_free(predictor);
    if (predicted_status != HAPCAL_STATUS_OK) return fail(robot);
    for (size_t t = 0; t < N_TIPS; t++) {
        char key[32];
        snprintf(key, sizeof key, "predicted%zu", t);
        print_pose(key, &predicted[t].pose);
        printf("predicted%zu_has_sigma %d\n", t, (int)predicted[t].has_sigma);
    }
    printf("uncertainty_note %s\n", note);

    /* --record PATH: a robot whose sidecar is a calibration record (values with their σ and
     * covariance, a region), tip ball_link: its prediction in the instrument frame with 1σ,
     * and the region flag at a reading past its training range. */
    if (record_path != NULL) {
        const char *record_tips[1] = {"ball_link"};
        HapcalRobot *record_robot = NULL;
        HapcalPredictor *record_predictor = NULL;
        HapcalTipPrediction record_predicted[1];
        double far[N_JOINTS];
        memcpy(far, q, sizeof far);
        far[1] = 1.6;
        size_t record_joint = 0;
        double record_distance = 0.0;
        HapcalStatus st = hapcal_robot_load(record_path, record_tips, 1, &record_robot);
        if (st == HAPCAL_STATUS_OK) st = hapcal_predictor_new(record_robot, HAPCAL_FRAME_INSTRUMENT, &record_predictor);
        if (st == HAPCAL_STATUS_OK) st = hapcal_predictor_predict(record_predictor, q, n, record_predicted, 1);
        if (st == HAPCAL_STATUS_OK) {
            st = hapcal_predictor_outside_region(record_predictor, far, n, &record_joint, &record_distance);
        }
        if (st == HAPCAL_STATUS_OK) {
            print_pose("record_predicted0", &record_predicted[0].pose);
            double sigma[2] = {record_predicted[0].sigma_m, record_predicted[0].sigma_rad};
            print_row("record_predicted0_sigma", sigma, 2);
            printf("record_predictor %d %d %zu\n", (int)hapcal_predictor_basis(record_predictor),
                   (int)hapcal_predictor_has_uncertainty(record_predictor),
                   hapcal_predictor_n_values(record_predictor));
            printf("record_region %zu %.17g\n", record_joint, record_distance);
        }
        hapcal_predictor_free(record_predictor);
        hapcal_robot_free(record_robot);
        if (st != HAPCAL_STATUS_OK) return fail(robot);
    }

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
        clock_gettime(CLOCK_MONOTONIC, &t0);
        for (long i = 0; i < bench; i++) {
            qb[0] = q[0] + 1e-9 * (double)(i & 1023);
            hapcal_robot_deflected_spatial_jacobian(robot, 0, qb, n, spatial, &pose, NULL);
            sink += pose.translation_m[0] + spatial[0];
        }
        clock_gettime(CLOCK_MONOTONIC, &t1);
        ns = (double)(t1.tv_sec - t0.tv_sec) * 1e9 + (double)(t1.tv_nsec - t0.tv_nsec);
        printf("bench_ns_per_deflected_jacobian %.1f (%ld calls, checksum %.6g)\n", ns / (double)bench,
               bench, sink);
    }

    hapcal_robot_free(robot);
    return 0;
}
