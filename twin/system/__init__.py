"""The operating-system edge, used by every layer: files written atomically and run record
names (``jsonio``), process groups started and stopped whole (``processes``).
"""
