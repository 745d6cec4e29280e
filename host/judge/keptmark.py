"""A set-pose's kept check into the report (issue #11, ``host.judge.setposekept``): named in its
``set_pose`` event, a failed one a FAIL of the whole log, one not made said why."""

from __future__ import annotations

from typing import Any

from odocan.host.judge.setposekept import Kept


def mark_kept(report: dict[str, Any], checks: dict[int, Kept]) -> None:
    """Put each check (by the index of the life the set-pose opened: its event's ``life``)
    into its ``set_pose`` event (``kept``); a failed one FAILs the report, named there. One
    not made: ``kept`` null, why in ``kept_not_judged`` and the event's detail."""
    for event in report["events"]:
        if event["kind"] != "set_pose" or event.get("life") not in checks or all(
                event[name] is not None for name in ("x_m", "y_m", "heading_rad")):
            continue  # every field set: the life starts exactly there, nothing kept
        check = checks[event["life"]]
        if isinstance(check, str):
            event["kept"], event["kept_not_judged"] = None, check
            event["detail"] += f"; what the APPLY kept not checked: {check} (judged by its fit)"
            continue
        event["kept"] = check
        if check is not None and not check["passed"]:
            report["passed"] = False
            event["detail"] += (
                f"; FAIL: the firmware's pose jumped {check['position_jump_m']:.4f} m, "
                f"{check['heading_jump_rad']:.5f} rad at an APPLY that kept "
                f"{', '.join(check['fields_kept'])} (nothing staged for them in this firmware "
                "life): it set what it was not given")

