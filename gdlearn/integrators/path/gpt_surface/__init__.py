"""gpt's lockstep base/offset kernels on surfaces (no media)."""
