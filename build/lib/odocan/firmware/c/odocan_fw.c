/* The shared-library ABI (odocan_fw.h) over the ECU (ecu.h): a thin layer, no logic of its own. */
#include "odocan_fw.h"

#include "ecu.h"
#include "hal.h"

uint32_t odocan_fw_abi_version(void)
{
    return ODOCAN_FW_ABI_VERSION;
}

size_t odocan_fw_state_size(void)
{
    return sizeof(struct odom_ecu);
}

int odocan_fw_init(void *fw, size_t size, const uint32_t params[6], odocan_fw_tx_fn tx,
                   void *tx_ctx)
{
    if (size < sizeof(struct odom_ecu)) {
        return -1;
    }
    struct robot_params p = {
        .counts_per_rev = params[0],
        .wheel_radius_left_nm = params[1],
        .wheel_radius_right_nm = params[2],
        .wheelbase_nm = params[3],
        .counter_bits = params[4],
        .integrator = params[5],
    };
    ecu_init((struct odom_ecu *)fw, tx, tx_ctx, &p);
    return 0;
}

void odocan_fw_rx_isr(void *fw, uint32_t can_id, uint32_t len, const uint8_t *data)
{
    ecu_isr_can_rx((struct odom_ecu *)fw, can_id, data, (size_t)len);
}

void odocan_fw_bus_state(void *fw, bool bus_off)
{
    ecu_isr_bus_state((struct odom_ecu *)fw, bus_off);
}

void odocan_fw_rx_overrun(void *fw)
{
    ecu_isr_rx_overrun((struct odom_ecu *)fw);
}

void odocan_fw_tick(void *fw, uint64_t now_us)
{
    /* the ECU's timer is a free-running u32 microsecond counter: it wraps, as the MCU's does */
    ecu_tick_at((struct odom_ecu *)fw, (uint32_t)(now_us & 0xFFFFFFFFu));
}

uint32_t odocan_fw_state(const void *fw)
{
    return (uint32_t)((const struct odom_ecu *)fw)->state;
}

uint32_t odocan_fw_errors(const void *fw)
{
    return ((const struct odom_ecu *)fw)->errors;
}

uint32_t odocan_fw_ticks(const void *fw)
{
    return ((const struct odom_ecu *)fw)->ticks;
}
