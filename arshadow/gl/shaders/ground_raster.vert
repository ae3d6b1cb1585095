#version 330 core
// The ground occlusion map (arshadow.gl.sky.GLGroundRaster): the mesh projected along the sky direction u_dir
// onto the ground z = 0 (the texel grid u_grid); depth = the distance from the ground along u_dir, so the
// nearest face a ground point sees along it wins. Face culling keeps a closed mesh's faces turned towards
// the ground (n . d < 0): their projections cover the same shadow as the light-facing faces', and the
// nearest of them is the face the ground point sees. Clipped at z = 0 when the mesh reaches below it.
in vec3 in_pos;         // world (ground frame), metres, x and y relative to the grid's centre
uniform vec3 u_dir;     // unit direction towards the sky, z > 0
uniform vec3 u_grid;    // (x0, y0) of the grid relative to its centre, side in metres
uniform float u_tmax;   // largest distance along u_dir (depth range)
out float gl_ClipDistance[1];
void main() {
    gl_ClipDistance[0] = in_pos.z;
    float t = in_pos.z / u_dir.z;
    vec2 g = in_pos.xy - t * u_dir.xy;
    gl_Position = vec4((g - u_grid.xy) / u_grid.z * 2.0 - 1.0, t / u_tmax * 2.0 - 1.0, 1.0);
}
