#!/usr/bin/env bash
# raise-rmem.sh WHO: raises the kernel's cap on a socket's receive buffer (net.core.rmem_max) to
# 16 MiB when run as root, and says so on stderr (as WHO) when the cap stays lower.
# Debian caps it at 208 KiB. vdyn's readers ask for more (a recorder 32 MiB, a Python client 16
# MiB): a server's world description (2 MB) comes in one burst, a lockstep server sends ~1.7k
# states a second in bursts, and states are best effort, so a reader descheduled for ~100 ms
# behind a 208 KiB buffer loses what the kernel cannot hold. Whether the write took is read back:
# sysctl exits 0 in some containers where it changed nothing.
want=16777216
who="${1:-vdyn}"
rmem_max() { cat /proc/sys/net/core/rmem_max 2>/dev/null || echo 0; }
if [ "$(rmem_max)" -lt "$want" ]; then
  if [ "$(id -u)" = 0 ]; then sysctl -qw net.core.rmem_max="$want" 2>/dev/null || true; fi
  if [ "$(rmem_max)" -lt "$want" ]; then
    echo "$who: net.core.rmem_max is $(rmem_max) bytes: a reader that falls ~0.1 s behind loses" \
         "best-effort states; as root: sysctl -w net.core.rmem_max=$want (on a container, on its" \
         "host)" >&2
  else
    echo "$who: net.core.rmem_max raised to $want bytes (sockets' receive buffers)" >&2
  fi
fi
exit 0
