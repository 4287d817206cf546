"""The platform every Heft process stands on: the protocol (messages, keys, wire),
typed configuration, the Zenoh session, processes and the ``heft`` command."""
