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

int odocan_fw_init(void *fw, size_t size, const uint32_t params[7], odocan_fw_tx_fn tx,
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
        .max_wheel_speed_mm_s = params[6],
    };
    ecu_init((struct odom_ecu *)fw, tx, tx_ctx, &p);
    return 0;
}

/* No EPOCH cell: reads "never written", refuses every write (the firmware fails closed). */
static uint32_t no_nvm_read(void *nvm_ctx)
{
    (void)nvm_ctx;
    return 0u;
}

static bool no_nvm_write(void *nvm_ctx, uint32_t epoch)
{
    (void)nvm_ctx;
    (void)epoch;
    return false;
}

int odocan_fw_provision_secoc(void *fw, const uint8_t *key, uint32_t key_len,
                              odocan_fw_nvm_read_fn read_epoch,
                              odocan_fw_nvm_write_fn write_epoch, void *nvm_ctx)
{
    struct odom_ecu *ecu = (struct odom_ecu *)fw;
    if (ecu->secoc_on || ecu->ticks != 0u) {
        return -1;
    }
    struct freshness_nvm nvm = {no_nvm_read, no_nvm_write, NULL};
    if (read_epoch != NULL && write_epoch != NULL) {
        nvm.read_epoch = read_epoch;
        nvm.write_epoch = write_epoch;
        nvm.ctx = nvm_ctx;
    }
    ecu_provision_secoc(ecu, key, key_len == AES128_KEY_BYTES ? AES128_KEY_BYTES : 0u, nvm);
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
