"""Tests of servosurf.metrology."""
