# The reference firmware for the ATmega328P (firmware/, gcc-avr) and its test on an emulated chip:
# fw-harness (simavr) runs the ELF with its UART on a pseudo-terminal, and the unchanged
# omni-trigger scans against it (bin/omni-trigger/tests/firmware.rs, ignored by a plain
# `cargo test`). One test at a time: the harness keeps real time.
.PHONY: fw fw-test
EXTRA_TESTS += fw-test
FW_OUT := $(CURDIR)/firmware/build

fw:
	$(MAKE) -C firmware all harness OUT=$(FW_OUT)

fw-test: fw
	FW_HARNESS=$(FW_OUT)/fw-harness FW_ELF=$(FW_OUT)/omni-fw.elf \
		$(CARGO) test -p omni-trigger --test firmware -- --ignored --test-threads=1
