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

#endif
