/* Errors are state, not exceptions: a u32 error mask of sticky bits (firmware/errors.py). */
#ifndef ODOCAN_ERRORS_H
#define ODOCAN_ERRORS_H

/* Bits of the firmware's u32 error mask (the ERROR_MASK signal of ODOM_STATUS). */
#define ERROR_NONE 0u
#define ERROR_SATURATION (1u << 0)       /* an arithmetic result was clamped to its width */
#define ERROR_CONFIG_INVALID (1u << 1)   /* a configuration was refused */
#define ERROR_ENCODER_TIMEOUT (1u << 2)  /* no fresh WHEEL_ENCODERS for the watchdog period */
#define ERROR_MAILBOX_OVERFLOW (1u << 3) /* the receive mailbox was full: a frame was dropped */
#define ERROR_E2E_ERROR (1u << 4)        /* a frame failed its CRC or sequence check */
#define ERROR_BUS_OFF (1u << 6)          /* the CAN controller reported bus-off */
#define ERROR_TIME_LOST (1u << 7)        /* the tick ran WATCHDOG_TICKS periods or more late */
#define ERROR_IMPLAUSIBLE_STEP (1u << 8) /* an encoder step beyond the max wheel speed */
#define ERROR_COUNTER_RESET (1u << 9)    /* counters restarted, or an ambiguous step: re-primed */
#define ERROR_POSE_UNCERTAIN (1u << 10)  /* merged steps' worst-case error passed the tolerance */

/* Why the state is not OK (the REASON signal of ODOM_STATUS): the last cause of DEGRADED (or
 * FAULT); REASON_NONE while OK. */
enum reason {
    REASON_NONE = 0,
    REASON_ENCODER_TIMEOUT = 1,  /* no accepted WHEEL_ENCODERS for the watchdog period */
    REASON_TIME_LOST = 2,        /* the firmware itself did not run for the watchdog period */
    REASON_MAILBOX_OVERFLOW = 3, /* received frames were dropped: the mailbox was full */
    REASON_IMPLAUSIBLE_STEP = 4, /* an encoder step beyond the maximum wheel speed was refused */
    REASON_COUNTER_RESET = 5,    /* counters restarted (controller reboot), or an ambiguous step */
    REASON_CONFIG_INVALID = 6,   /* the boot configuration was refused (FAULT) */
    REASON_POSE_UNCERTAIN = 7    /* merged steps' worst-case error passed the tolerance: latched */
};

#endif
