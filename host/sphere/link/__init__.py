"""The link to the sphere: the serial port (:mod:`.port`), commands and replies (:mod:`.device`), captures of the
byte stream (:mod:`.capture`), the bootloader (:mod:`.bootloader`), what ``sphere monitor`` shows (:mod:`.monitor`),
the device settings by name (:mod:`.device_settings`) and the baud switch's host side (:mod:`.baud`)."""
