#version 330
// The colour is multiplied by the destination alpha pass 1 wrote (blending does it), and the
// alpha goes back to 1.
out vec4 f_color;
void main() { f_color = vec4(0.0, 0.0, 0.0, 1.0); }
