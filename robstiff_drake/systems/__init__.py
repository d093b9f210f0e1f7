"""Drake LeafSystems of the closed loop, one file per block.  Each wraps a
plain-numpy model from robstiff_drake.model and runs at its own sample rate."""
