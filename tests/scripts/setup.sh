#!/usr/bin/env bash
# Install what the build, the emulators and the tests need, if missing.
# Idempotent: a second run installs nothing. Sourced by scripts/run.sh and
# tests/scripts/test.sh.
#
#   SETUP_PROFILE=run   : AVR toolchain + what simavr builds with (+ avrdude
#                         when flashing)
#   SETUP_PROFILE=test  : everything the test command uses
set -euo pipefail

say() { printf '\033[1m[setup]\033[0m %s\n' "$*"; }
die() { printf '\033[1;31m[setup] error:\033[0m %s\n' "$*" >&2; exit 1; }

profile=${SETUP_PROFILE:-test}

# --- Rust toolchains -------------------------------------------------------
command -v rustup >/dev/null || die "rustup is not installed: see https://rustup.rs, then run this again."
# rust-toolchain.toml pins one nightly (with rust-src, llvm-tools and the
# thumbv7em target) for every build; install it if missing.
if ! rustup toolchain list | grep -q "^$(sed -n 's/^channel = "\(.*\)"/\1/p' rust-toolchain.toml)"; then
  say "installing the pinned toolchain of rust-toolchain.toml"
  rustup toolchain install || die "could not install the toolchain rust-toolchain.toml names"
fi
# (Its components and target too, if the toolchain came without them.)
if ! rustup component list --installed 2>/dev/null | grep -q '^rust-src'; then
  say "adding rust-src (for -Z build-std=core on avr-none)"
  rustup component add rust-src || die "could not add rust-src"
fi
if ! rustup target list --installed | grep -qx thumbv7em-none-eabihf; then
  say "adding the thumbv7em-none-eabihf target (the SKR Pro build)"
  rustup target add thumbv7em-none-eabihf || die "could not add the thumbv7em-none-eabihf target"
fi
if ! rustup component list --installed | grep -q '^llvm-tools'; then
  say "adding llvm-tools (llvm-size / llvm-objcopy for the ARM build)"
  rustup component add llvm-tools || die "could not add llvm-tools"
fi

# --- Debian packages -------------------------------------------------------
# avr-gcc links the AVR firmware and avr-size measures it; the simavr-based
# bench (the run command's simulator and the tests) builds simavr from source
# (gcc and make, libelf, clang for bindgen); QEMU runs the firmware in the
# tests; avrdude flashes a real board; python3-venv hosts Printrun's printcore.
packages=(gcc-avr avr-libc binutils-avr gcc make libelf-dev libclang-dev pkg-config libzstd-dev zlib1g-dev)
if [ "$profile" = test ]; then
  packages+=(qemu-system-misc qemu-system-arm python3-venv)
fi
if [ "${SETUP_FLASH:-0}" = 1 ]; then
  packages+=(avrdude)
fi
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  command -v apt-get >/dev/null || die "missing packages (${missing[*]}) and no apt-get: install them by hand."
  sudo=""
  if [ "$(id -u)" != 0 ]; then
    command -v sudo >/dev/null || die "missing packages (${missing[*]}): run as root or install sudo."
    sudo="sudo"
  fi
  say "installing Debian packages: ${missing[*]}"
  # QEMU packages and the AVR ones are installed in separate calls: together
  # they can fail on machines that ship a newer qemu-utils (DESIGN.md).
  install() { DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y --no-install-recommends "$@"; }
  # Each QEMU package in its own call (DESIGN.md: together they can fail).
  for p in $(printf '%s\n' "${missing[@]}" | grep '^qemu' || true); do
    if ! install "$p" >/tmp/ferrostep-apt.log 2>&1; then
      say "apt-get install $p failed; refreshing the package lists and retrying"
      $sudo apt-get update >/tmp/ferrostep-apt-update.log 2>&1 || die "apt-get update failed (see /tmp/ferrostep-apt-update.log)"
      install "$p" >/tmp/ferrostep-apt.log 2>&1 || die "could not install $p (see /tmp/ferrostep-apt.log)"
    fi
  done
  set -- $(printf '%s\n' "${missing[@]}" | grep -v '^qemu' || true)
  if [ $# -gt 0 ] && ! install "$@" >/tmp/ferrostep-apt.log 2>&1; then
    say "apt-get install failed; refreshing the package lists and retrying"
    $sudo apt-get update >/tmp/ferrostep-apt-update.log 2>&1 || die "apt-get update failed (see /tmp/ferrostep-apt-update.log)"
    install "$@" >/tmp/ferrostep-apt.log 2>&1 || die "could not install $* (see /tmp/ferrostep-apt.log)"
  fi
fi
say "toolchains and packages are in place"
