"""Simulators the scaledp stack drives as robots: each runs in this Python process and answers
the bridge protocol (``protocol.py``) on stdin/stdout; the Rust side (``sim/src/bridge/``)
publishes its cameras and joints over Zenoh, records it, and evaluates policies on it."""
