#version 330
// Lines are unlit: the colour interpolated along the segment.
in vec4 v_color;
out vec4 f_color;
void main() { f_color = v_color; }
