"""The team's security: its certificates and the Zenoh router's access control."""
