"""The 3DM-GX3-25: byte protocol, stream framer, serial link, session and simulated device."""
