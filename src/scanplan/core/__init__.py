"""The record and the physics every stage shares: the plan record, the scan's parameters
(ScanSpec, D, alpha, advance), the sensor's datasheet, the reward, the cycle time, files and limits.
"""
