"""Colours and labels of rendered frames (no pygame here)."""

#: RGB colours used in frames (tests look for some of them).
COLORS = {
    "background": (16, 22, 36),
    "grid": (32, 42, 62),
    "text": (225, 230, 240),
    "panel": (8, 12, 22),
    "agent": (70, 160, 255),
    "traffic": (235, 235, 235),
    "clear": (70, 190, 110),
    "conflict": (255, 185, 30),
    "los": (240, 55, 45),
    "nmac": (255, 60, 255),
    "trail": (120, 135, 160),
    "track": (255, 225, 90),
    "prediction": (150, 220, 255),
    "advice": (255, 110, 180),
    "mode_straight": (235, 235, 235),
    "mode_left": (80, 220, 230),
    "mode_right": (255, 140, 60),
}

#: (colour key, legend label) of an aircraft's protected circle, in order of precedence
#: from the least to the most severe state.
STATE_LABELS = (
    ("clear", "clear"),
    ("conflict", "conflict alert"),
    ("los", "loss of separation"),
    ("nmac", "NMAC"),
)

#: colours of the mode-probability bars (straight, left, right)
MODE_COLORS = (COLORS["mode_straight"], COLORS["mode_left"], COLORS["mode_right"])
