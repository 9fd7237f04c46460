# Helpers for scripts/deps.d/NN-*.sh (sourced by scripts/deps.sh; not run on its own).
#   need_apt PKG...   installs the Debian packages that are missing (apt-get update at most once)
#   need_pip PKG...   installs Python packages into the project's venv ($VENV, default .venv)
VENV=${VENV:-.venv}
_apt_updated=0

as_root() {
  if [ "$(id -u)" = 0 ]; then "$@"
  elif command -v sudo >/dev/null; then sudo "$@"
  else echo "deps: '$*' needs root; run it as root or install the packages yourself" >&2; return 1
  fi
}

need_apt() {
  local missing=()
  for pkg in "$@"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "deps: installing Debian packages: ${missing[*]}" >&2
  if [ "$_apt_updated" = 0 ]; then as_root apt-get update -qq; _apt_updated=1; fi
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
}

need_pip() {
  if [ ! -x "$VENV/bin/python" ]; then
    echo "deps: creating the Python venv $VENV" >&2
    python3 -m venv "$VENV"
  fi
  local missing=()
  for pkg in "$@"; do
    "$VENV/bin/python" -m pip show -q "${pkg%%[=<>]*}" >/dev/null 2>&1 || missing+=("$pkg")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "deps: installing Python packages into $VENV: ${missing[*]}" >&2
  "$VENV/bin/python" -m pip install -q --disable-pip-version-check "${missing[@]}"
}
