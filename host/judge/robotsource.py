"""Where the robot a judge judges with came from, one word each for ``analyze``/``replay``
(``host.cli.robotchoice``) and the live judges (``host.judge.liverobot``): a module of its own,
so that ``analyze`` imports no live judge to name them."""

DEFAULT_ROBOT = "pmir"  # without --robot, when no PROFILE page picks one
GIVEN, FROM_PAGE, DEFAULT = "--robot", "PROFILE page", "default"  # ``source``
GIVEN_AS = {GIVEN: "--robot", FROM_PAGE: "its PROFILE page's robot",
            DEFAULT: "the default robot"}  # a mismatch line's name for where the robot came from
