"""The bus facts the judges build on, read of the DBC once at import (rule: the DBC is the single
source of truth for frames).

Cycle times (``GenMsgCycleTime``, ms), frames per cycle (``E2EFramesPerCycle``), E2E COUNTER
laps (2 ** the COUNTER signal's length: one lap for every message, ``dbcfacts.e2e_counter_lap``),
the ODOM_STATUS page numbers and the APPLY codes (the ``VAL_`` tables), UPTIME's LSB and the
encoder counts' wire width: each judge once restated them as its own literal. Here they are
read of the DBC at ``sim.contract.DBC_PATH`` (``ODOCAN_DBC``;
``odocan analyze/monitor --dbc PATH`` make PATH that DBC before any judge is imported:
``host.cli.dbcfirst``) through the judge's plan of it (``dbcplan.default_plan``: no cantools on
a warm cache), so a DBC edited there is followed. What is read, and how, is said once, in
``host.protocol.dbcfacts`` (``JudgeFacts``), which also refuses a DBC named later in the same
process whose facts differ. Plain module constants: the per-frame paths read a global, as they
read the literals before. A DBC that lacks one of them is refused at import (``DbcFactError``),
never patched with a default.
"""

from __future__ import annotations

from odocan.host.protocol.dbcfacts import ENC_MESSAGE as ENC_MESSAGE
from odocan.host.protocol.dbcfacts import MS_PER_S as MS_PER_S
from odocan.host.protocol.dbcfacts import POSE_MESSAGE as POSE_MESSAGE
from odocan.host.protocol.dbcfacts import STATUS_MESSAGE as STATUS_MESSAGE
from odocan.host.protocol.dbcfacts import judge_facts
from odocan.host.protocol.dbcplan import default_plan

US_PER_MS = 1000
FACTS = judge_facts(default_plan())  # the facts of this process's DBC, read once

ENC_CYCLE_MS = FACTS.enc_cycle_ms  # 10
ENC_CYCLE_S = ENC_CYCLE_MS / MS_PER_S
ENC_PERIOD_US = ENC_CYCLE_MS * US_PER_MS  # 10 000: the period the firmware's steps are bounded in
ENC_PERIODS_PER_S = MS_PER_S // ENC_CYCLE_MS  # 100: CTRL_UPTIME's second in encoder periods
ENC_COUNTER_LAP = FACTS.enc_counter_lap  # 16: a 4-bit E2E COUNTER, every COUNTER's lap
ENC_COUNTER_MASK = ENC_COUNTER_LAP - 1  # 0xF: a COUNTER step mod the lap (a power of two)
ENC_WIRE_COUNTER_BITS = FACTS.enc_wire_counter_bits  # 24
POSE_CYCLE_MS = FACTS.pose_cycle_ms  # 20
POSE_FRAMES_PER_CYCLE = FACTS.pose_frames_per_cycle  # 1
POSE_PERIOD_S = POSE_CYCLE_MS / POSE_FRAMES_PER_CYCLE / MS_PER_S  # one pose frame to the next
POSE_COUNTER_LAP = FACTS.pose_counter_lap  # 16
POSE_ENC_COUNTER_LAP = FACTS.pose_enc_counter_lap  # 16: ENC_COUNTER echoes WHEEL_ENCODERS'
STATUS_CYCLE_MS = FACTS.status_cycle_ms  # 100
STATUS_CYCLE_S = STATUS_CYCLE_MS / MS_PER_S  # one summary to the next
STATUS_FRAMES_PER_CYCLE = FACTS.status_frames_per_cycle  # 2: the summary and a page
STATUS_COUNTER_LAP = FACTS.status_counter_lap  # 16
FRESHNESS_CYCLE_MS = FACTS.freshness_cycle_ms  # 1000
UPTIME_LSB_MS = FACTS.uptime_lsb_ms  # 1000
SUMMARY_PAGE = FACTS.summary_page  # 0
TOTALS_PAGE = FACTS.totals_page  # 1
ENC_E2E_PAGE = FACTS.enc_e2e_page  # 2
PROFILE_PAGE = FACTS.profile_page  # 6
APPLY_FIELD = FACTS.apply_field  # 15
APPLY_PARAM = FACTS.apply_param  # 15
