#!/usr/bin/env bash
# Installs the Debian packages cnc_bridge needs (scripts/debian-packages.txt), skipping what is
# already installed, so a second run costs a second. Needs root or sudo for the install itself.
# A package counts as present when it is installed or an installed package provides it (e.g.
# NodeSource's nodejs provides npm and conflicts with Debian's npm).
#   scripts/setup.sh                   install what is missing to build, test and run
#   scripts/setup.sh --runtime         only what a machine computer needs to run an installed
#                                      package (scripts/debian-runtime-packages.txt)
#   scripts/setup.sh [--runtime] --check   only list what is missing; exit status 1 if anything is
# Without --runtime it also builds the reference MTConnect agent the round-trip test runs
# (scripts/build_cppagent.sh: cppagent v1.8.0.3 from its tag, installed outside the repository).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
check_only=0
list=debian-packages.txt
for option in "$@"; do
  case "$option" in
    --check) check_only=1 ;;
    --runtime) list=debian-runtime-packages.txt ;;
    *) echo "usage: setup.sh [--runtime] [--check]" >&2; exit 2 ;;
  esac
done
mapfile -t wanted < <(grep -vE '^\s*(#|$)' "$here/$list")

# Installed packages and the names they provide, one per line ("npm (= 9.2)" -> "npm").
present=$(dpkg-query -W -f='${db:Status-Abbrev} ${Package} ${Provides}\n' 2>/dev/null |
  awk '$1 == "ii" { $1 = ""; print }' | sed -E 's/\([^)]*\)//g; s/[:,]/ /g' | tr ' ' '\n' | grep -v '^$' | sort -u)
missing=()
for pkg in "${wanted[@]}"; do
  grep -qxF "$pkg" <<<"$present" || missing+=("$pkg")
done
# The reference MTConnect agent (not a Debian package), for building and testing only.
agent_step() {
  [[ $list == debian-packages.txt ]] || return 0
  if [[ $check_only -eq 1 ]]; then
    "$here/build_cppagent.sh" --check
  else
    "$here/build_cppagent.sh"
  fi
}
if [[ ${#missing[@]} -eq 0 ]]; then
  echo "setup: all ${#wanted[@]} Debian packages present"
  agent_step
  exit 0
fi
if [[ $check_only -eq 1 ]]; then
  echo "setup: ${#missing[@]} Debian packages missing: ${missing[*]}"
  agent_step || true
  exit 1
fi
sudo=""
if [[ $(id -u) -ne 0 ]]; then
  command -v sudo >/dev/null || { echo "setup: run as root (or install sudo) to install: ${missing[*]}" >&2; exit 1; }
  sudo="sudo"
fi
echo "setup: installing ${#missing[@]} Debian packages: ${missing[*]}"
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
agent_step
