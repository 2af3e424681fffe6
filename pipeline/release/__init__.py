"""Release of the scenario set: build, verify, certify, reproduce, export to LeRobot."""
