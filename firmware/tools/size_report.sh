#!/bin/sh
# Prints the flash and RAM an AVR ELF uses and fails when less than 25 % of either is free.
# usage: size_report.sh FILE.elf FLASH_BYTES RAM_BYTES
set -eu
elf=$1 flash_total=$2 ram_total=$3
avr-size -A "$elf" | awk -v ft="$flash_total" -v rt="$ram_total" '
  $1 == ".text" { text = $2 } $1 == ".data" { data = $2 }
  $1 == ".bss" { bss = $2 } $1 == ".noinit" { noinit = $2 }
  END {
    flash = text + data; ram = data + bss + noinit
    printf "flash: %6d of %6d bytes (%4.1f %%), %4.1f %% free\n", flash, ft, 100 * flash / ft, 100 - 100 * flash / ft
    printf "RAM:   %6d of %6d bytes (%4.1f %%), %4.1f %% free for the stack\n", ram, rt, 100 * ram / rt, 100 - 100 * ram / rt
    if (flash > 0.75 * ft || ram > 0.75 * rt) { print "less than 25 % free: too big"; exit 1 }
  }'
