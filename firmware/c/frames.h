/* The frames the ECU packs and unpacks (firmware/frames.py), on the code cantools generates from
 * dbc/odocan.dbc (dbc/odocan.c): this layer adds what the DBC cannot say, as frames.py does:
 * saturation of out-of-range values (SATURATION in the error mask), the raw value of an unknown
 * multiplexer, and the E2E Profile 2 seal with each message's DataIDList. */
#ifndef ODOCAN_FRAMES_H
#define ODOCAN_FRAMES_H

#include <stddef.h>
#include <stdint.h>

#include "dbc/odocan.h"
#include "e2e.h"

#define WHEEL_ENCODERS_ID ODOCAN_WHEEL_ENCODERS_FRAME_ID
#define MOTOR_CMD_ID ODOCAN_MOTOR_CMD_FRAME_ID
#define ODOM_POSE_X_ID ODOCAN_ODOM_POSE_X_FRAME_ID
#define ODOM_POSE_Y_ID ODOCAN_ODOM_POSE_Y_FRAME_ID
#define ODOM_TWIST_ID ODOCAN_ODOM_TWIST_FRAME_ID
#define NAV_GOAL_ID ODOCAN_NAV_GOAL_FRAME_ID
#define NAV_STATUS_ID ODOCAN_NAV_STATUS_FRAME_ID
#define ODOM_SET_POSE_ID ODOCAN_ODOM_SET_POSE_FRAME_ID
#define ODOM_CONFIG_ID ODOCAN_ODOM_CONFIG_FRAME_ID
#define ODOM_ACK_ID ODOCAN_ODOM_ACK_FRAME_ID
#define ODOM_STATUS_ID ODOCAN_ODOM_STATUS_FRAME_ID
#define ODOM_AUTH_ID ODOCAN_ODOM_AUTH_FRAME_ID
#define ODOM_FRESHNESS_ID ODOCAN_ODOM_FRESHNESS_FRAME_ID
#define CAN_ID_MAX 0x7FFu
#define NAV_QUEUE_DEPTH_MAX 16

/* E2E slots: DataIDList[c] = (slot << 4) | c (dbc/README.md). */
#define WHEEL_ENCODERS_E2E_SLOT 1u
#define MOTOR_CMD_E2E_SLOT 2u
#define ODOM_POSE_X_E2E_SLOT 3u
#define ODOM_POSE_Y_E2E_SLOT 4u
#define ODOM_TWIST_E2E_SLOT 5u
#define ODOM_SET_POSE_E2E_SLOT 6u
#define ODOM_CONFIG_E2E_SLOT 7u
#define ODOM_ACK_E2E_SLOT 8u
#define ODOM_STATUS_E2E_SLOT 9u
#define NAV_GOAL_E2E_SLOT 10u
#define NAV_STATUS_E2E_SLOT 11u
#define ODOM_AUTH_E2E_SLOT 12u
#define ODOM_FRESHNESS_E2E_SLOT 13u

enum set_pose_field { SET_POSE_X = 0, SET_POSE_Y = 1, SET_POSE_HEADING = 2, SET_POSE_APPLY = 15 };
enum config_param { PARAM_COUNTS_PER_REV = 0, PARAM_WHEEL_RADIUS_LEFT = 1,
                    PARAM_WHEEL_RADIUS_RIGHT = 2, PARAM_WHEELBASE = 3, PARAM_COUNTER_BITS = 4,
                    PARAM_INTEGRATOR = 5, PARAM_MAX_WHEEL_SPEED = 6 /* u16 mm/s */,
                    PARAM_APPLY = 15 };
enum ack_result { ACK_RESULT_ACK = 0, ACK_RESULT_NACK = 1 };
enum status_page { PAGE_SUMMARY = 0, PAGE_FRAME_TOTALS = 1, PAGE_E2E_WHEEL_ENCODERS = 2,
                   PAGE_E2E_ODOM_SET_POSE = 3, PAGE_E2E_ODOM_CONFIG = 4, PAGE_E2E_NAV_GOAL = 5,
                   PAGE_PROFILE = 6 };

/* A multiplexed request's record: counter, multiplexer, value read per field. */
struct mux_record {
    uint8_t counter;
    uint8_t field;
    int64_t value;
};

void data_ids_of_slot(unsigned slot, uint8_t ids[DATA_ID_COUNT]);

struct odom_auth; /* secoc.h */

void unpack_odom_auth(const uint8_t data[8], struct odom_auth *out);
void pack_odom_freshness(uint8_t out[8], uint8_t counter, int64_t cause, uint64_t fv,
                         uint32_t *errors);

void unpack_wheel_encoders(const uint8_t data[8], uint8_t *counter, uint32_t *left_count,
                           uint32_t *right_count, uint8_t *ctrl_uptime_s);
void unpack_odom_set_pose(const uint8_t data[8], struct mux_record *out);
void unpack_odom_config(const uint8_t data[8], struct mux_record *out);
void unpack_nav_goal(const uint8_t data[8], struct mux_record *out, uint8_t *mode,
                     uint8_t *append, uint8_t *no_final_heading, uint8_t *goal_id);

void pack_motor_cmd(uint8_t out[8], uint8_t counter, int64_t left_speed_mm_s,
                    int64_t right_speed_mm_s, uint32_t *errors);
void pack_odom_pose_x(uint8_t out[8], uint8_t counter, uint8_t enc_counter, int64_t x_100um,
                      uint32_t heading_bam16, uint32_t *errors);
void pack_odom_pose_y(uint8_t out[8], uint8_t counter, uint8_t enc_counter, int64_t y_100um,
                      int32_t turns, uint32_t *errors);
void pack_odom_twist(uint8_t out[8], uint8_t counter, uint8_t enc_counter,
                     int64_t linear_vel_mm_s, int64_t angular_vel_mrad_s, uint64_t distance_mm,
                     uint32_t *errors);
void pack_nav_status(uint8_t out[8], uint8_t counter, int64_t state, int64_t goal_id,
                     int64_t queue_depth, int64_t distance_mm, int32_t heading_error_bam16,
                     uint32_t *errors);
void pack_odom_ack(uint8_t out[8], uint8_t counter, uint8_t request_counter, int64_t request_id,
                   uint8_t request_field, int64_t result, int64_t reason, uint32_t *errors);
void pack_odom_status_summary(uint8_t out[8], uint8_t counter, int64_t state, int64_t integrator,
                              uint32_t error_mask, int64_t uptime_s, uint32_t *errors,
                              int64_t reason);
void pack_odom_status_frame_totals(uint8_t out[8], uint8_t counter, uint32_t lost,
                                   uint32_t rejected, uint32_t overflowed);
void pack_odom_status_profile(uint8_t out[8], uint8_t counter, uint32_t max_wheel_speed_mm_s,
                              uint32_t profile_crc);
void pack_odom_status_e2e(uint8_t out[8], uint8_t counter, enum status_page page, uint32_t ok,
                          uint32_t lost, uint32_t repeated, uint32_t crc_error,
                          uint32_t wrong_sequence);

#endif
