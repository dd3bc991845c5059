"""The image's HEALTHCHECK: exit 0 when the service's /healthz answers 200, 1 otherwise.

Asks the address uvicorn listens on (UVICORN_HOST, UVICORN_PORT), loopback for a wildcard.
"""

import os
import sys
import urllib.request

host = os.environ.get("UVICORN_HOST", "127.0.0.1")
if host in ("", "0.0.0.0"):
    host = "127.0.0.1"
elif host == "::":
    host = "::1"
if ":" in host:
    host = f"[{host}]"
url = f"http://{host}:{os.environ.get('UVICORN_PORT', '8000')}/healthz"
try:
    with urllib.request.urlopen(url, timeout=4) as response:
        sys.exit(0 if response.status == 200 else 1)
except Exception as error:  # any failure is "unhealthy", said on stderr for `docker inspect`
    print(f"{url}: {error}", file=sys.stderr)
    sys.exit(1)
