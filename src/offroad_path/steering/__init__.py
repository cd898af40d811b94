"""The end-to-end baseline the paper compares against: PilotNet regressing the steering angle."""
