"""What the Foxglove SDK logs about its clients, made useful to the person reading the node's log.

The SDK (Rust, through Python logging) reports each bad message a client
sends, and each refused connection, as one log line. Two things are done to
those lines here, once at import:

* lines about bad client input are rate-limited per logger
  (:data:`SDK_CLIENT_LOGGERS`): a client looping on bad input must not flood
  the log;
* a refused WebSocket handshake, logged by the SDK as only "handshake
  failed", is rewritten to say what the node needs: the ``foxglove.sdk.v1``
  subprotocol, i.e. a Foxglove app that speaks it (clients that offer only the
  older ``foxglove.websocket.v1``, such as Foxglove Studio 1.x builds and
  Lichtblick, get HTTP 400).
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Dict, Tuple

__all__ = ["SDK_CLIENT_LOGGERS", "SDK_SERVER_LOGGER", "SUBPROTOCOL", "HANDSHAKE_HINT", "THROTTLE_S"]

#: the one WebSocket subprotocol foxglove-sdk's server accepts
SUBPROTOCOL = "foxglove.sdk.v1"
#: what a refused client's log line adds
HANDSHAKE_HINT = (
    f"this node's Foxglove server speaks only the {SUBPROTOCOL} WebSocket subprotocol: connect with the "
    f"Foxglove app (desktop, or app.foxglove.dev) in a current release; clients that offer only "
    f"foxglove.websocket.v1 (Foxglove Studio 1.x builds, Lichtblick) get HTTP 400"
)
#: the SDK logger that reports refused connections
SDK_SERVER_LOGGER = "foxglove.websocket.server"
#: seconds per rate-limit window
THROTTLE_S = 2.0

#: loggers the SDK (Rust, through Python logging) reports bad client input on, one line per message
SDK_CLIENT_LOGGERS = ("foxglove.websocket.connected_client", "foxglove.websocket.connected_client.poller")


class _SdkLogLimit(logging.Filter):
    """At most ``burst`` records per ``period`` seconds per SDK logger, then one summary.

    The SDK logs every malformed frame, unknown opcode or unknown channel a
    client sends (and answers it with a status message). A client looping on
    bad input must not flood the node's log: the first few lines show what is
    wrong, the rest are counted.
    """

    def __init__(self, burst: int = 5, period: float = THROTTLE_S) -> None:
        super().__init__()
        self.burst, self.period = burst, period
        self._window: Dict[str, Tuple[float, int]] = {}  # logger -> (window start, records in it)
        self._lock = threading.Lock()

    def filter(self, record: logging.LogRecord) -> bool:
        now = time.monotonic()
        with self._lock:
            start, count = self._window.get(record.name, (now, 0))
            if now - start >= self.period:
                if count > self.burst:
                    record.msg = f"{record.getMessage()} ({count - self.burst} similar suppressed)"
                    record.args = ()
                start, count = now, 0
            self._window[record.name] = (start, count + 1)
            return count < self.burst


_SDK_LOG_LIMIT = _SdkLogLimit()
for _name in SDK_CLIENT_LOGGERS:
    if _SDK_LOG_LIMIT not in logging.getLogger(_name).filters:
        logging.getLogger(_name).addFilter(_SDK_LOG_LIMIT)




class _HandshakeHint(logging.Filter):
    """Rewrite the SDK's "Dropping client ...: handshake failed" into a line that says what is needed."""

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        if "handshake failed" in message:
            record.msg, record.args = f"foxglove: refused a client ({message}): {HANDSHAKE_HINT}", ()
            record.levelno, record.levelname = logging.WARNING, "WARNING"
        return True


_HANDSHAKE_HINT = _HandshakeHint()
if not any(isinstance(f, _HandshakeHint) for f in logging.getLogger(SDK_SERVER_LOGGER).filters):
    logging.getLogger(SDK_SERVER_LOGGER).addFilter(_HANDSHAKE_HINT)
