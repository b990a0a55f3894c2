"""The guided tour of the book's Sect. 7.4 as a demo (``loci demo``): separate processes on a
loopback Zenoh bus, the tutor played by a script (or a person), outputs in one folder."""
