/* Fixed-point trigonometry on binary angles: sincos_q30 and atan2_bam32 (firmware/trig.py). */
#ifndef ODOCAN_TRIG_H
#define ODOCAN_TRIG_H

#include <stdint.h>

#define ONE_Q30 ((int32_t)1 << 30)
#define QUARTER_BAM32 ((int64_t)1 << 30)
#define HALF_BAM32 ((int64_t)1 << 31)

void sincos_q30(uint32_t angle_bam32, int32_t *sin_out_q30, int32_t *cos_out_q30);
int32_t sin_q30(uint32_t angle_bam32);
int32_t cos_q30(uint32_t angle_bam32);
int32_t atan2_bam32(int64_t y, int64_t x);

#endif
