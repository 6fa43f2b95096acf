#!/bin/busybox sh
# initramfs /init of the QEMU guest: load USB gadget modules, mount the host's root over 9p,
# chroot into it and run tests/qemu/guest.sh, then power off.
/bin/busybox --install -s /bin
mount -t proc proc /proc
mount -t sysfs sys /sys
mount -t devtmpfs dev /dev
for m in $(cat /modules.txt); do insmod /lib/modules/$m.ko || echo "insmod $m failed"; done
ARGS=$(cat /args.txt)
mkdir -p /host
mount -t 9p -o trans=virtio,version=9p2000.L,ro hostroot /host || { echo "QEMU-USB-RESULT: fail 9p"; poweroff -f; }
mount -t proc proc /host/proc
mount -t sysfs sys /host/sys
mount -t devtmpfs dev /host/dev
mount -t tmpfs tmpfs /host/run
mount -t configfs none /host/sys/kernel/config
chroot /host /bin/sh $ARGS
poweroff -f
