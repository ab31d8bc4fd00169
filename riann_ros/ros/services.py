"""Calling the nodes' services from a tool or a test (rclpy clients)."""

from __future__ import annotations

import time
from typing import Any


def call_service(client: Any, request: Any, timeout: float, resend_every: float = 2.0) -> Any | None:
    """Call a service and wait up to ``timeout`` s for the answer; None when none came.

    The request is sent again every ``resend_every`` s: with Fast DDS, ``wait_for_service`` can return
    before the server has matched the client's response reader, and the first answer is then lost (seen
    once in a few hundred CI runs). Use it for idempotent requests only (``~/reset``, ``~/restart``,
    set_parameters).
    """
    futures = [client.call_async(request)]
    end = time.monotonic() + timeout
    next_send = time.monotonic() + resend_every
    try:
        while time.monotonic() < end:
            for f in futures:
                if f.done():
                    return f.result()
            if time.monotonic() >= next_send:
                futures.append(client.call_async(request))
                next_send += resend_every
            time.sleep(0.002)
        return None
    finally:
        for f in futures:
            if not f.done():
                client.remove_pending_request(f)
