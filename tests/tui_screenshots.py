"""The README's screenshots of ``odocan monitor``: 80×24 tmux panes, captured with colours.

    python -m tests.tui_screenshots docs/img

Three scenes, each ``odocan monitor`` in a process of its own in an 80×24 tmux pane listening
to a loopback ``udp_multicast`` channel fed by the lockstep rig (``tests.test_tui_tmux``):

* ``monitor-healthy.png``: the rig driving, firmware OK;
* ``monitor-degraded.png``: the motor controller bus-off from 5 s (``busoff=5:60`` on
  its sends): encoders silent, the firmware DEGRADED with ENCODER_TIMEOUT;
* ``monitor-stale.png``: the sender stopped: the silence warning, the status STALE.

Two more of ``odocan monitor --broker`` (the MQTT fleet view) in the same 80×24 pane, watching
``odocan fleet -n 3`` (robot001..003, with its embedded broker) and ``odocan fleet -n 4 --shard
4/4`` (robot004 alone) on that broker, each fleet a process of its own:

* ``fleet-healthy.png``: four robots publishing, worst error first;
* ``fleet-stale.png``: robot004's process stopped (SIGSTOP: a hung robot whose connection stays
  up, so no offline status comes), the row dimmed as ``stale Ns``.

``tmux capture-pane -e`` gives the screen with its colour escapes; rich parses them
(``Text.from_ansi``) and Pillow (matplotlib's dependency) draws each cell of the 80×24 grid in
DejaVu Sans Mono with rich's MONOKAI terminal colours (an SVG through librsvg lost the spaces
after coloured words).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import can
from PIL import Image, ImageDraw, ImageFont
from rich.ansi import AnsiDecoder
from rich.color import Color
from rich.console import Console
from rich.style import Style
from rich.terminal_theme import MONOKAI

from odocan.host.mqtt.broker import free_loopback_port
from tests.test_realtime import _udp_channel
from tests.test_tui_tmux import COLUMNS, ROWS, START_TIMEOUT_S, Pane, Sender, monitor_command

FONT = "/usr/share/fonts/truetype/dejavu/DejaVuSansMono.ttf"
FONT_BOLD = "/usr/share/fonts/truetype/dejavu/DejaVuSansMono-Bold.ttf"
FONT_PX = 15
THEME = MONOKAI


def save_png(pane: Pane, path: Path) -> None:
    """The pane as it is now, cell by cell, to ``path`` (PNG)."""
    font, bold = ImageFont.truetype(FONT, FONT_PX), ImageFont.truetype(FONT_BOLD, FONT_PX)
    cell_w, cell_h = round(font.getlength("M")), round(FONT_PX * 1.3)
    margin = 8
    # RGB as _colours gives it (the triplet's .rgb is a CSS string: never equal to a tuple).
    background = tuple(THEME.background_color)
    image = Image.new("RGB", (2 * margin + COLUMNS * cell_w, 2 * margin + ROWS * cell_h),
                      background)
    draw = ImageDraw.Draw(image)
    # One decoder for the whole screen: tmux leaves out escapes a row inherits from the last.
    for y, text in enumerate(AnsiDecoder().decode("\n".join(pane.rows(ansi=True)))):
        for x in range(min(len(text.plain), COLUMNS)):
            style = text.get_style_at_offset(_CONSOLE, x)
            fg, bg = _colours(style)
            left, top = margin + x * cell_w, margin + y * cell_h
            if bg != background:
                draw.rectangle((left, top, left + cell_w - 1, top + cell_h - 1), fill=bg)
            draw.text((left, top + 2), text.plain[x], fill=fg, font=bold if style.bold else font)
    image.save(path, optimize=True)
    print(f"{path}: {path.stat().st_size // 1024} KiB")


_CONSOLE = Console(file=open(os.devnull, "w"))  # noqa: SIM115 (lives as long as the script)


def _colours(style: Style) -> tuple[tuple[int, int, int], tuple[int, int, int]]:
    """Foreground and background RGB of a style (dim blends towards the background)."""
    fg = (style.color or Color.default()).get_truecolor(THEME, foreground=True)
    bg = (style.bgcolor or Color.default()).get_truecolor(THEME, foreground=False)
    if style.reverse:
        fg, bg = bg, fg
    if style.dim:
        fg = fg._replace(red=(fg.red + bg.red) // 2, green=(fg.green + bg.green) // 2,
                         blue=(fg.blue + bg.blue) // 2)
    return (fg.red, fg.green, fg.blue), (bg.red, bg.green, bg.blue)


def scene(out_dir: Path, name: str, faults: str, ready: str, stop_sender: bool) -> None:
    """Run the monitor in a pane until its screen shows ``ready`` in the firmware line."""
    argv, kwargs = _udp_channel()
    bus = can.Bus(**kwargs)
    sender = Sender(bus, faults=faults)
    pane = Pane(monitor_command(argv))
    try:
        sender.start()
        pane.wait_for(lambda r: r[1].startswith("firmware ") and "no ODOM" not in r[1],
                      START_TIMEOUT_S)
        time.sleep(3.0)
        if stop_sender:
            sender.halt()
        pane.wait_for(lambda r: ready in r[1] or ready in r[6], 30)
        time.sleep(1.0)
        save_png(pane, out_dir / f"monitor-{name}.png")
    finally:
        sender.halt()
        pane.close()
        bus.shutdown()


@contextmanager
def _fleet(*argv: str) -> Iterator[subprocess.Popen[bytes]]:
    """``odocan fleet ARGV`` in a process of its own, stopped (and continued, to die) at the end."""
    command = [sys.executable, "-m", "odocan", "fleet", *argv]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        yield process
    finally:
        process.send_signal(signal.SIGCONT)
        process.terminate()
        process.wait(30)


def fleet_scenes(out_dir: Path) -> None:
    """The fleet view with four healthy robots, then with robot004 hung (stale)."""
    port = free_loopback_port()
    url = f"mqtt://127.0.0.1:{port}"
    with _fleet("-n", "3", "--port", str(port), "--duration", "300", "--seed", "4"):
        time.sleep(5.0)  # the embedded broker is up before the second fleet connects
        with _fleet("-n", "4", "--shard", "4/4", "--broker", url, "--duration", "300",
                    "--seed", "4") as hung:
            pane = Pane(monitor_command(["--broker", url]))
            try:
                pane.wait_for(lambda r: "4 robots" in r[0] and "stale" not in r[0]
                              and sum(" OK " in row for row in r) == 4, 60)
                time.sleep(3.0)
                save_png(pane, out_dir / "fleet-healthy.png")
                hung.send_signal(signal.SIGSTOP)
                pane.wait_for(lambda r: "(1 stale)" in r[0] and "stale 5s" in "".join(r), 60)
                save_png(pane, out_dir / "fleet-stale.png")
            finally:
                pane.close()


def main(out_dir: Path) -> None:
    """Make the five screenshots in ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    scene(out_dir, "healthy", "", "firmware OK", stop_sender=False)
    scene(out_dir, "degraded", "busoff=5:60", "DEGRADED", stop_sender=False)
    scene(out_dir, "stale", "", "since the last frame", stop_sender=True)
    fleet_scenes(out_dir)


if __name__ == "__main__":
    if sys.argv[2:] == ["--fleet"]:  # only the two fleet screenshots
        fleet_scenes(Path(sys.argv[1]))
    else:
        main(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/img"))
