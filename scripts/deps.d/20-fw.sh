# The reference firmware (firmware/, mk/fw.mk): the AVR toolchain, and simavr for the test
# harness (its headers land in /usr/include/simavr; libsimavr links against libelf).
need_apt make gcc gcc-avr binutils-avr avr-libc libsimavr-dev libelf-dev pkg-config
