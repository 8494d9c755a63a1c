"""Errors a user can cause and fix, as opposed to bugs.

The CLI prints a :class:`UserError` as one line and exits with status 2, with no traceback.
"""


def escape(text: str) -> str:
    """``text`` with every non-printable character (newline, tab, ANSI escape, ...) written
    as its Python escape (``\\n``, ``\\t``, ``\\x1b``): what a user typed is echoed on one line
    and cannot move the cursor or colour the terminal. Printable Unicode (``≥``, ``µ``) stays."""
    return "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in text)


class UserError(ValueError):
    """Bad input from a user: a malformed scenario, an unknown name, a NaN in an action.

    The message says what and where (file, field, value) in one line. It is escaped here
    (:func:`escape`), the one place: keys, values and file names taken from the input may
    hold newlines or terminal escapes, and every message is echoed through this class.
    """

    def __init__(self, message: str = ""):
        super().__init__(escape(str(message)))
