"""Logging filters for the settings' LOGGING (the project's own; no app imports them)."""

import logging

from django.core.exceptions import PermissionDenied


class OneLine(logging.Filter):
    """Log an expected refusal (a 403: PermissionDenied) as one line with its reason, not a traceback: a refusal
    is the role matrix working, and a 30-line traceback per refused click buries the lines that matter."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.exc_info and isinstance(record.exc_info[1], PermissionDenied):
            record.msg = f"{record.getMessage()}: {record.exc_info[1]}"
            record.args = None
            record.exc_info = record.exc_text = None
        return True
