#!/usr/bin/env bash
# Install or update the omnisort cell service on the cell PC (Debian/Ubuntu with systemd).
#
#   sudo deploy/install.sh [--start] [--wheelhouse DIR] [--dry-run]
#
# --wheelhouse DIR (or --offline DIR) installs without network: pip takes this project and
# every dependency from the wheels in DIR only (--no-index --find-links DIR); build DIR on a
# connected machine with `make wheelhouse` (see deploy/README.md). --dry-run prints the pip
# commands it would run and changes nothing (no root needed).
#
# Idempotent: run it again after pulling a new version. It creates the system user `omnisort`
# (groups video and dialout for the camera and the serial laser), /etc/omnisort (config,
# never overwritten), /var/lib/omnisort (calibration) and /var/log/omnisort (.rrd run logs),
# a virtual environment in /opt/omnisort/venv with this checkout installed, a random service
# token in /etc/omnisort/token, and the systemd unit. Paths can be changed with PREFIX,
# CONF_DIR, STATE_DIR, LOG_DIR and UNIT_DIR; PYTHON picks the interpreter (>= 3.11).
set -euo pipefail

SRC=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PREFIX=${PREFIX:-/opt/omnisort}
CONF_DIR=${CONF_DIR:-/etc/omnisort}
STATE_DIR=${STATE_DIR:-/var/lib/omnisort}
LOG_DIR=${LOG_DIR:-/var/log/omnisort}
UNIT_DIR=${UNIT_DIR:-/etc/systemd/system}
PYTHON=${PYTHON:-python3}
SERVICE_USER=omnisort
START=0
WHEELHOUSE=
DRY_RUN=0

while [[ $# -gt 0 ]]; do
    case "$1" in
        --start) START=1 ;;
        --dry-run) DRY_RUN=1 ;;
        --wheelhouse|--offline)
            if [[ $# -lt 2 || -z $2 ]]; then
                echo "install.sh: $1 needs a folder of wheels" >&2
                exit 2
            fi
            WHEELHOUSE=$2
            shift
            ;;
        -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
        *) echo "install.sh: unknown argument $1" >&2; exit 2 ;;
    esac
    shift
done

log() { printf 'install.sh: %s\n' "$*"; }

# pip's source: the package index, or only the wheels of the wheelhouse (no network at all).
PIP_SOURCE=()
if [[ -n $WHEELHOUSE ]]; then
    if ! compgen -G "$WHEELHOUSE/omnisort_hw-*.whl" >/dev/null; then
        echo "install.sh: $WHEELHOUSE holds no omnisort_hw wheel (build it with make wheelhouse)" >&2
        exit 2
    fi
    WHEELHOUSE=$(cd "$WHEELHOUSE" && pwd)
    PIP_SOURCE=(--no-index --find-links "$WHEELHOUSE")
fi
PIP=("$PREFIX/venv/bin/python" -m pip install --quiet "${PIP_SOURCE[@]}")

# Online: a newer pip, then this checkout built and installed. Offline: the venv's pip as it is
# (a newer one is only on the index) and the project's wheel from the wheelhouse (building the
# checkout would need setuptools from the network), reinstalled even at an unchanged version.
pip_commands() {
    if [[ -z $WHEELHOUSE ]]; then
        "$@" "${PIP[@]}" --upgrade pip
        "$@" "${PIP[@]}" --upgrade "$SRC"
    else
        "$@" "${PIP[@]}" --upgrade omnisort-hw
        "$@" "${PIP[@]}" --upgrade --force-reinstall --no-deps omnisort-hw
    fi
}

if [[ $DRY_RUN -eq 1 ]]; then
    pip_commands echo
    exit 0
fi

if [[ $(id -u) -ne 0 ]]; then
    echo "install.sh: run as root (sudo $0)" >&2
    exit 1
fi
if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
    echo "install.sh: $PYTHON is older than 3.11; set PYTHON=/path/to/python3.11" >&2
    exit 1
fi

# User and groups: video for /dev/video*, dialout for serial ports; no login, no home of its own.
for group in video dialout; do
    getent group "$group" >/dev/null || groupadd --system "$group"
done
if ! getent group "$SERVICE_USER" >/dev/null; then
    groupadd --system "$SERVICE_USER"
    log "created group $SERVICE_USER"
fi
if ! id -u "$SERVICE_USER" >/dev/null 2>&1; then
    useradd --system --gid "$SERVICE_USER" --home-dir "$STATE_DIR" --no-create-home \
        --shell /usr/sbin/nologin --comment "omnisort cell service" "$SERVICE_USER"
    log "created user $SERVICE_USER"
fi
usermod --append --groups video,dialout "$SERVICE_USER"

# Directories: config readable by the service only; state and logs writable by it only.
install -d -m 0755 "$PREFIX" "$PREFIX/share"
install -d -o root -g "$SERVICE_USER" -m 0750 "$CONF_DIR"
install -d -o "$SERVICE_USER" -g "$SERVICE_USER" -m 0750 "$STATE_DIR" "$LOG_DIR"

# Virtual environment with this checkout installed (not editable: /opt stays read-only).
if [[ ! -x "$PREFIX/venv/bin/python" ]]; then
    "$PYTHON" -m venv "$PREFIX/venv"
    log "created $PREFIX/venv"
fi
pip_commands
"$PREFIX/venv/bin/python" -m compileall -q "$PREFIX/venv" >/dev/null || true
rm -rf "$PREFIX/share/deploy"
cp -r "$SRC/deploy" "$PREFIX/share/deploy"
log "installed omnisort $("$PREFIX/venv/bin/python" -c 'import omnisort_hw; print(omnisort_hw.__version__)')"

# Configuration and token: created once, never overwritten.
if [[ ! -f "$CONF_DIR/cell.toml" ]]; then
    install -o root -g "$SERVICE_USER" -m 0640 "$SRC/deploy/cell.example.toml" "$CONF_DIR/cell.toml"
    log "wrote $CONF_DIR/cell.toml from the example: edit it for this cell"
fi
if [[ ! -f "$CONF_DIR/token" ]]; then
    (umask 077 && "$PYTHON" -c 'import secrets; print(secrets.token_urlsafe(32))' >"$CONF_DIR/token")
    chown root:"$SERVICE_USER" "$CONF_DIR/token"
    chmod 0640 "$CONF_DIR/token"
    log "wrote a random token to $CONF_DIR/token (use token_file = \"$CONF_DIR/token\")"
fi

# systemd units: the service, and the operator interface beside it (its own process).
install -m 0644 "$SRC/deploy/omnisort.service" "$UNIT_DIR/omnisort.service"
install -m 0644 "$SRC/deploy/omnisort-ui.service" "$UNIT_DIR/omnisort-ui.service"
if [[ -d /run/systemd/system ]]; then
    systemctl daemon-reload
    systemctl enable omnisort.service omnisort-ui.service >/dev/null
    if [[ $START -eq 1 ]]; then
        systemctl restart omnisort.service omnisort-ui.service
        log "started: systemctl status omnisort omnisort-ui; journalctl -u omnisort -f"
    else
        log "enabled; start with: systemctl start omnisort omnisort-ui"
    fi
else
    log "systemd is not running here: units installed in $UNIT_DIR but not enabled"
fi
