# GenICam frame source (omni-trigger --camera aravis:ID, cargo feature `aravis`): the Aravis
# library and headers found through pkg-config (its .pc file also needs libusb's), and
# aravis-tools for arv-fake-gv-camera-0.8, the GigE Vision camera the tests run on `lo`, and
# iproute2 for `ip`, which brings `lo` up in the network namespace of the discovery test.
need_apt pkg-config libaravis-dev libusb-1.0-0-dev aravis-tools iproute2
