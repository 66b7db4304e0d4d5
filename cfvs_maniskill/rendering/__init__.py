"""Off-screen rendering set-up: a real GPU when there is one, SwiftShader (CPU Vulkan) otherwise."""
