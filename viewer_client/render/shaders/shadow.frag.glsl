#version 330 core
// Depth only: the colour attachment is GL_NONE.
void main() {}
