# The reference firmware for the ATmega328P (firmware/, gcc-avr) and its test on an emulated chip:
# fw-harness (simavr) runs the ELF with its UART on a pseudo-terminal, and the unchanged
# omni-trigger talks to it (bin/omni-trigger/tests/firmware.rs, ignored by a plain `cargo test`).
# One test at a time: the harness keeps real time.
#   fw-test       every firmware test (make test): protocol, refusals, retries, STOP, info, host
#                 disconnect -> lasers off, and full scans paired with frames at 60/30 rpm,
#                 with corrupted lines and with a stalled motor
#   fw-test-scan  the scans alone: the frames' times need the simulation at real speed (the
#                 harness warns "behind real time" when it falls behind; the test then retries)
.PHONY: fw fw-test fw-test-scan
EXTRA_TESTS += fw-test
FW_OUT := $(CURDIR)/firmware/build
FW_ENV := FW_HARNESS=$(FW_OUT)/fw-harness FW_ELF=$(FW_OUT)/omni-fw.elf
FW_SCAN_TESTS := scans_at_two_polygon_speeds corrupted_lines_in_both_directions a_stalled_motor

fw:
	$(MAKE) -C firmware all harness OUT=$(FW_OUT)

fw-test: fw
	$(FW_ENV) $(CARGO) test $(WORKSPACE) --test firmware -- --ignored --test-threads=1

fw-test-scan: fw
	$(FW_ENV) $(CARGO) test $(WORKSPACE) --test firmware -- --ignored --test-threads=1 $(FW_SCAN_TESTS)
