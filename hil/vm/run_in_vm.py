"""Run a command inside a throw-away Linux VM that has SocketCAN and vcan0.

This machine's kernel has no CAN support, so the SocketCAN tier of the tests
runs in a Debian kernel booted under QEMU with the host's own userspace
(virtme-ng): the same files, the same virtualenv, a kernel with vcan. The
script installs what it needs (Debian: qemu-system-x86, linux-image-amd64,
busybox-static; PyPI: virtme-ng, into its own venv), boots the kernel
(software emulation; KVM is not used), loads vcan, brings up vcan0 as a
CAN FD interface, runs the command and returns its exit status.

    python3 hil/vm/run_in_vm.py [--out build/vm] -- .venv/bin/python -m pytest -m vcan tests

The command runs from the project root; only --out is writable from inside
the VM (its path is exported as PYRHONN_VM_OUT). Timing measured inside the
emulated VM says nothing about real hardware; functional results do.
"""
from __future__ import annotations

import argparse
import glob
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
APT_PACKAGES = {"qemu-system-x86_64": "qemu-system-x86", "busybox": "busybox-static"}


def ensure_system_packages() -> None:
    need = [pkg for tool, pkg in APT_PACKAGES.items() if shutil.which(tool) is None]
    if not glob.glob("/boot/vmlinuz-*"):
        need.append("linux-image-amd64")
    if not need:
        return
    if os.geteuid() != 0:
        raise SystemExit(f"run_in_vm: missing Debian packages {need} and not root to install them")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    subprocess.run(["apt-get", "update", "-o", "DPkg::Lock::Timeout=900"], check=True, env=env)
    subprocess.run(["apt-get", "install", "-y", "-o", "DPkg::Lock::Timeout=900", "--no-install-recommends", *need],
                   check=True, env=env)


def ensure_virtme(venv: Path) -> Path:
    vng = venv / "bin" / "vng"
    if not vng.exists():
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run([str(venv / "bin" / "pip"), "install", "--quiet", "virtme-ng"], check=True)
    return vng


def newest_kernel() -> str:
    kernels = sorted(glob.glob("/boot/vmlinuz-*"))
    if not kernels:
        raise SystemExit("run_in_vm: no kernel in /boot")
    return kernels[-1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "vm", help="folder writable from the VM")
    ap.add_argument("--venv", type=Path, default=ROOT / "build" / "virtme-venv", help="where virtme-ng is installed")
    ap.add_argument("--timeout", type=int, default=1800, help="seconds before the VM is killed")
    ap.add_argument("command", nargs=argparse.REMAINDER, help="command to run inside (after --)")
    args = ap.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        ap.error("give the command to run inside the VM after --")
    ensure_system_packages()
    vng = ensure_virtme(args.venv.resolve())
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    status_file = out / "exit-status"
    status_file.unlink(missing_ok=True)
    inner = " && ".join([
        "modprobe vcan",
        "ip link add dev vcan0 type vcan",
        "ip link set vcan0 mtu 72",  # CAN FD frames
        "ip link set up vcan0",
        f"cd {shlex.quote(str(ROOT))}",
        f"export PYRHONN_VM_OUT={shlex.quote(str(out))} PYRHONN_REQUIRE_VCAN=1 "
        f"MPLCONFIGDIR={shlex.quote(str(out / 'matplotlib'))}",  # the guest's $HOME is read-only
    ]) + f"; {shlex.join(command)}; echo $? > {shlex.quote(str(status_file))}"
    env = {**os.environ, "PATH": f"{vng.parent}:{os.environ.get('PATH', '')}"}
    try:
        proc = subprocess.run([str(vng), "--run", newest_kernel(), "--disable-kvm", "--memory", "2G",
                               "--rwdir", str(out), "--exec", inner], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, timeout=args.timeout)
    except subprocess.TimeoutExpired:
        print(f"run_in_vm: the VM did not finish within {args.timeout} s", file=sys.stderr)
        return 124
    sys.stdout.write(proc.stdout)
    if not status_file.exists():
        print(f"run_in_vm: the command did not complete inside the VM (vng exit {proc.returncode})",
              file=sys.stderr)
        return proc.returncode or 1
    return int(status_file.read_text().strip() or 1)


if __name__ == "__main__":
    sys.exit(main())
