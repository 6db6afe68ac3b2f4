"""identification: SINDy-with-control on pysindy for quadrotor data."""
