#version 330 core
// Shadow volume faces only touch the stencil buffer (colour and depth writes are off).
void main() {
}
