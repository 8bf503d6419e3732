#!/bin/sh
# Entrypoint of the quadsitl image: runs `quadsitl sim` with container-friendly links.
# Every setting is an environment variable; extra arguments go to `quadsitl sim`
# (e.g. `--lockstep`, `--speed 2`, `--param MPC_XY_CRUISE=3`).
#
#   QUADSITL_GCS_HOST  where QGroundControl and MAVSDK run (default host.docker.internal)
#   QUADSITL_GCS       ground-station link  (default udpout:$QUADSITL_GCS_HOST:14550)
#   QUADSITL_API       API/offboard link    (default udpout:$QUADSITL_GCS_HOST:14540)
#   QUADSITL_HIL       motor-command link   (default udpin:0.0.0.0:4560)
#   QUADSITL_IN        link for stations that connect in (default udpin:0.0.0.0:14551)
#   QUADSITL_LOGS      telemetry log folder (default /data/logs; "none" disables it)
#   QUADSITL_SIGNING_PASSPHRASE  require MAVLink 2 signing (read by quadsitl itself)
#   QUADSITL_BIN       the quadsitl executable (default: quadsitl on PATH)
set -eu
host="${QUADSITL_GCS_HOST:-host.docker.internal}"
exec "${QUADSITL_BIN:-quadsitl}" sim \
    --gcs "${QUADSITL_GCS:-udpout:$host:14550}" \
    --api "${QUADSITL_API:-udpout:$host:14540}" \
    --hil "${QUADSITL_HIL:-udpin:0.0.0.0:4560}" \
    --link "${QUADSITL_IN:-udpin:0.0.0.0:14551}" \
    --logs "${QUADSITL_LOGS:-/data/logs}" \
    "$@"
