"""Boot a QEMU guest with a real Linux USB stack and stream a frame file through it.

    python tests/qemu/run_qemu.py FRAMES.bin [--work DIR] [--timeout S]

The guest (Debian 12's kernel, software emulation) loads dummy_hcd and FunctionFS,
mounts this machine's root read-only over 9p, runs ``tests/qemu/ffs_device.py``
as a USB gadget (the emulated controller) and sends FRAMES.bin to it with pyusb
and libusb (``send_frame_file``). Prints the guest's ``QEMU-USB-*`` lines; exit
status 0 if the device accepted every frame in order, 77 if QEMU, busybox or the
kernel package is not available, 1 otherwise.

Needs (Debian): qemu-system-x86, busybox-static, and apt access for
``apt-get download`` of the kernel package (cached in --work).
"""

from __future__ import annotations

import argparse
import glob
import gzip
import os
import re
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
MODULES = [
    "virtio_ring",
    "virtio",
    "virtio_pci_modern_dev",
    "virtio_pci_legacy_dev",
    "virtio_pci",
    "netfs",
    "fscache",
    "9pnet",
    "9pnet_virtio",
    "9p",
    "usb-common",
    "usbcore",
    "udc-core",
    "dummy_hcd",
    "configfs",
    "libcomposite",
    "usb_f_fs",
    "virtio-rng",
]


def _skip(msg: str) -> int:
    print(f"QEMU-USB-RESULT: skipped ({msg})")
    return 77


def _kernel(work: str) -> tuple[str, str] | None:
    """(vmlinuz, modules dir) of Debian 12's 6.1 kernel, downloaded once into ``work``."""
    root = os.path.join(work, "kernel")
    found = glob.glob(os.path.join(root, "boot", "vmlinuz-*"))
    if not found:
        out = subprocess.run(
            ["apt-cache", "search", "--names-only", r"^linux-image-6\.1\.0-[0-9]+-amd64-unsigned$"],
            capture_output=True,
            text=True,
        ).stdout.split()
        names = sorted(
            {w for w in out if w.startswith("linux-image-")}, key=lambda n: int(re.findall(r"6\.1\.0-(\d+)", n)[0])
        )
        if not names:
            return None
        r = subprocess.run(["apt-get", "download", names[-1]], cwd=work, capture_output=True, text=True)
        debs = glob.glob(os.path.join(work, "linux-image-*.deb"))
        if r.returncode != 0 or not debs:
            return None
        subprocess.run(["dpkg", "-x", debs[0], root], check=True)
        found = glob.glob(os.path.join(root, "boot", "vmlinuz-*"))
    mods = glob.glob(os.path.join(root, "lib", "modules", "*"))
    return (found[0], mods[0]) if found and mods else None


def _cpio_newc(entries: list[tuple[str, int, bytes]]) -> bytes:
    """A newc cpio archive of (name, mode, data) entries (directories have no data)."""
    out = bytearray()
    ino = 1
    for name, mode, data in entries + [("TRAILER!!!", 0, b"")]:
        nb = name.encode() + b"\0"
        hdr = "070701" + "".join(f"{v:08x}" for v in (ino, mode, 0, 0, 1, 0, len(data), 0, 0, 0, 0, len(nb), 0))
        out += hdr.encode() + nb
        out += b"\0" * (-len(out) % 4)
        out += data
        out += b"\0" * (-len(out) % 4)
        ino += 1
    return bytes(out)


def _initramfs(work: str, modules_dir: str, args: str) -> str:
    busybox = shutil.which("busybox")
    entries = [(d, 0o40755, b"") for d in ("bin", "dev", "proc", "sys", "host", "lib", "lib/modules")]
    with open(busybox, "rb") as fh:
        entries.append(("bin/busybox", 0o100755, fh.read()))
    with open(os.path.join(HERE, "init.sh"), "rb") as fh:
        entries.append(("init", 0o100755, fh.read()))
    for m in MODULES:
        path = glob.glob(os.path.join(modules_dir, "**", m + ".ko"), recursive=True) or glob.glob(
            os.path.join(modules_dir, "**", m.replace("-", "_") + ".ko"), recursive=True
        )
        if not path:
            raise FileNotFoundError(f"kernel module {m} not found")
        with open(path[0], "rb") as fh:
            entries.append((f"lib/modules/{m}.ko", 0o100644, fh.read()))
    entries.append(("modules.txt", 0o100644, " ".join(MODULES).encode()))
    entries.append(("args.txt", 0o100644, args.encode()))
    out = os.path.join(work, "initrd.cpio.gz")
    with gzip.open(out, "wb", compresslevel=1) as fh:
        fh.write(_cpio_newc(entries))
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("frames")
    ap.add_argument("--work", default=os.path.join(os.environ.get("TMPDIR", "/tmp"), "cnc-interp-qemu"))
    ap.add_argument("--timeout", type=float, default=600.0)
    a = ap.parse_args()
    for tool in ("qemu-system-x86_64", "busybox", "apt-get", "dpkg"):
        if shutil.which(tool) is None:
            return _skip(f"{tool} not installed")
    os.makedirs(a.work, exist_ok=True)
    k = _kernel(a.work)
    if k is None:
        return _skip("Debian kernel package not available")
    vmlinuz, mods = k
    frames = os.path.abspath(a.frames)
    initrd = _initramfs(a.work, mods, f"{REPO}/tests/qemu/guest.sh {frames} {REPO}")
    # -cpu max: numpy needs x86-64-v2 (SSE4.2, POPCNT), which the default qemu64 model lacks
    cmd = [
        "qemu-system-x86_64",
        "-accel",
        "tcg",
        "-cpu",
        "max",
        "-m",
        "1024",
        "-smp",
        "2",
        "-kernel",
        vmlinuz,
        "-initrd",
        initrd,
        "-append",
        "console=ttyS0 panic=-1 quiet",
        "-nographic",
        "-no-reboot",
        "-device",
        "virtio-rng-pci",
        "-virtfs",
        "local,path=/,mount_tag=hostroot,security_model=none,readonly=on,multidevs=remap",
    ]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=a.timeout, stdin=subprocess.DEVNULL)
        text = p.stdout + p.stderr
    except subprocess.TimeoutExpired as exc:
        text = (exc.stdout or b"").decode(errors="replace") if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        print(text[-3000:])
        print("QEMU-USB-RESULT: fail timeout")
        return 1
    lines = [ln.strip() for ln in text.splitlines() if "QEMU-USB-" in ln]
    for ln in lines:
        print(ln[ln.index("QEMU-USB-") :])
    if not any(ln.endswith("QEMU-USB-RESULT: done") for ln in lines):
        print(text[-4000:])
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
