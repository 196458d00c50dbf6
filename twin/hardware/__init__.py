"""Drivers that implement ``twin.controller.MachineIO``."""
